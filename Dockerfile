# The wavecore service: docker build -t wavecore . && docker run -p 8000:8000 wavecore
#
# The image is set up by the same script as a developer's machine and CI
# (`bash scripts/run.sh setup`), so CI exercises every step of this build.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    WAVECORE_VENV=/opt/venv \
    NUMBA_CACHE_DIR=/opt/numba-cache

RUN useradd --create-home --uid 10001 --shell /usr/sbin/nologin wavecore

WORKDIR /app
COPY pyproject.toml README.md ./
COPY scripts ./scripts
COPY wavecore ./wavecore
COPY service ./service

# Set up, then compile the kernels once into the numba cache (the paths of colour and grey
# pictures at a quality and at a rate, curves and surfaces), so that a new container answers
# its first requests without a compile pause.
RUN bash scripts/run.sh setup \
    && /opt/venv/bin/python -c "import numpy as np, wavecore; \
rgb = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8); \
[wavecore.decode(wavecore.encode_image(rgb, **t)) for t in ({}, {'bpp': 2.0})]; \
wavecore.decode(wavecore.encode_image(rgb[:, :, 0], bpp=2.0)); \
wavecore.decode(wavecore.encode_curve(rgb[:, 0, :2] / 255.0)); \
wavecore.decode(wavecore.encode_surface(rgb / 255.0))" \
    && chown -R wavecore /opt/numba-cache

USER wavecore
EXPOSE 8000

# No curl in the slim image: the health check uses Python's standard library.
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD ["/opt/venv/bin/python", "-c", "import sys, urllib.request; r = urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4); sys.exit(r.status != 200)"]

# Limits and sizes come from WAVECORE_* variables (docs/deploy.md).
CMD ["/opt/venv/bin/wavecore", "serve", "--host", "0.0.0.0", "--port", "8000"]
