# The wavecore service: docker build -t wavecore . && docker run -p 8000:8000 wavecore
#
# The image is set up by the same script as a developer's machine and CI
# (`bash scripts/run.sh setup`), so CI exercises every step of this build.
FROM python:3.11-slim

# NUMBA_CPU_NAME=generic: the kernels in the image's numba cache are compiled for a portable
# x86-64 target, not for the build host's CPU, so a container on any other CPU loads them from
# the cache instead of compiling again (numba keys its cache by the CPU name and features, so
# the same variable is set at run time too).
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    WAVECORE_VENV=/opt/venv \
    NUMBA_CACHE_DIR=/opt/numba-cache \
    NUMBA_CPU_NAME=generic

RUN useradd --create-home --uid 10001 --shell /usr/sbin/nologin wavecore

WORKDIR /app
COPY pyproject.toml README.md ./
COPY scripts ./scripts
COPY wavecore ./wavecore
COPY service ./service

# Set up: install, then compile every kernel for every kind and dtype a bundle allows into the
# numba cache (`python -m wavecore.warmup`, with a progress line per step), so that a new
# container answers its first requests without a compile pause.
RUN bash scripts/run.sh setup \
    && chown -R wavecore /opt/numba-cache

USER wavecore
EXPOSE 8000

# No curl in the slim image: the health check uses Python's standard library.
# `wavecore serve` warms up (loads every kernel from the cache, a few seconds) before it listens.
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["/opt/venv/bin/python", "-c", "import sys, urllib.request; r = urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4); sys.exit(r.status != 200)"]

# Limits and sizes come from WAVECORE_* variables (docs/deploy.md).
CMD ["/opt/venv/bin/wavecore", "serve", "--host", "0.0.0.0", "--port", "8000"]
