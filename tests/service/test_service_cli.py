"""The ``wavecore`` command line, called as ``main([...])`` and once as a real process."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from service_helpers import circle, image_file, test_image

import wavecore
from service.cli import main


@pytest.fixture
def images(tmp_path: Path) -> Path:
    folder = tmp_path / "in"
    folder.mkdir()
    for i in range(3):
        (folder / f"img{i}.png").write_bytes(image_file(test_image((40 + i, 52), seed=i)))
    return folder


def test_encode_decode_one_image(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bundle = tmp_path / "one.wcb"
    assert main(["encode", str(images / "img0.png"), str(bundle), "--quality", "36"]) == 0
    assert wavecore.inspect(bundle.read_bytes())["psnr"] >= 36
    out = tmp_path / "one.png"
    assert main(["decode", str(bundle), str(out)]) == 0
    decoded = np.asarray(Image.open(out))
    assert np.array_equal(decoded, wavecore.decode(bundle.read_bytes()))
    assert main(["decode", str(bundle), str(tmp_path / "coarse.npy"), "--level", "1"]) == 0
    assert (
        np.load(tmp_path / "coarse.npy").shape
        == wavecore.decode(bundle.read_bytes(), level=1).shape
    )
    capsys.readouterr()
    assert main(["inspect", str(bundle)]) == 0
    text = capsys.readouterr().out
    assert "image 40×52 uint8" in text and "PSNR" in text
    assert main(["inspect", str(bundle), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "image"


def test_inspect_names_an_enlargement(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    picture = test_image((20, 26, 3)).repeat(4, axis=0).repeat(4, axis=1)
    Image.fromarray(picture).save(tmp_path / "pixel.png")
    bundle = tmp_path / "pixel.wcb"
    assert main(["encode", str(tmp_path / "pixel.png"), str(bundle), "--quality", "40"]) == 0
    capsys.readouterr()
    assert main(["inspect", str(bundle)]) == 0
    text = capsys.readouterr().out
    assert "image 80×104×3 uint8, format 7.0" in text
    assert "each pixel repeated 4 × 4" in text
    assert main(["decode", str(bundle), str(tmp_path / "out.png")]) == 0
    assert np.asarray(Image.open(tmp_path / "out.png")).shape == picture.shape


def test_lossless_is_exact(tmp_path: Path, images: Path) -> None:
    bundle = tmp_path / "exact.wcb"
    assert main(["encode", str(images / "img1.png"), str(bundle), "--lossless"]) == 0
    assert main(["decode", str(bundle), str(tmp_path / "exact.png")]) == 0
    original = np.asarray(Image.open(images / "img1.png"))
    assert np.array_equal(np.asarray(Image.open(tmp_path / "exact.png")), original)


def test_lossless_effort_max(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = images / "img2.png"
    original = np.asarray(Image.open(source))
    bundle = tmp_path / "max.wcb"
    assert main(["encode", str(source), str(bundle), "--lossless", "--effort", "max"]) == 0
    assert bundle.read_bytes() == wavecore.encode_image(original, lossless=True, effort="max")
    assert np.array_equal(wavecore.decode(bundle.read_bytes()), original)
    fast = tmp_path / "fast.wcb"
    assert main(["encode", str(source), str(fast), "--lossless", "--effort", "fast"]) == 0
    assert fast.read_bytes() == wavecore.encode_image(original, lossless=True, effort="fast")
    capsys.readouterr()
    # a value the library refuses, and max without --lossless, are reported, not raised
    assert (
        main(["encode", str(source), str(tmp_path / "x.wcb"), "--lossless", "--effort", "hard"])
        == 1
    )
    assert "effort must be one of 'default', 'max', 'fast', not 'hard'" in capsys.readouterr().err
    assert main(["encode", str(source), str(tmp_path / "y.wcb"), "--effort", "max"]) == 1
    assert "applies only with lossless" in capsys.readouterr().err


def test_a_folder_and_a_glob_give_a_table(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (images / "notes.png").write_text("not an image")
    out = tmp_path / "bundles"
    status = main(["encode", str(images), str(out), "--bpp", "1.5"])
    captured = capsys.readouterr()
    assert status == 1  # one input failed; the others are done
    assert sorted(p.name for p in out.iterdir()) == ["img0.wcb", "img1.wcb", "img2.wcb"]
    assert "3 of 4 done" in captured.out and "notes.png" in captured.out
    assert "4/4" in captured.err  # the progress bar
    for bundle in out.iterdir():
        assert wavecore.inspect(bundle.read_bytes())["bpp"] <= 1.5
    assert main(["decode", str(out / "*.wcb"), str(tmp_path / "decoded"), "--keep", "0.2"]) == 0
    assert len(list((tmp_path / "decoded").glob("*.png"))) == 3
    assert main(["inspect", str(out / "img*.wcb")]) == 0
    assert "3 of 3 done" in capsys.readouterr().out


def test_curves_and_surfaces(tmp_path: Path) -> None:
    points = circle(48)
    (tmp_path / "c.json").write_text(json.dumps({"points": points, "closed": True}))
    assert (
        main(["encode", str(tmp_path / "c.json"), str(tmp_path / "c.wcb"), "--tolerance", "1e-3"])
        == 0
    )
    assert wavecore.inspect((tmp_path / "c.wcb").read_bytes())["boundary"] == ["closed"]
    assert main(["decode", str(tmp_path / "c.wcb"), str(tmp_path / "c2.json")]) == 0
    back = np.array(json.loads((tmp_path / "c2.json").read_text())["points"])
    assert np.abs(back - np.array(points)).max() <= 1e-3

    grid = np.random.default_rng(4).random((12, 14))
    np.save(tmp_path / "s.npy", grid)
    cmd = ["encode", str(tmp_path / "s.npy"), str(tmp_path / "s.wcb"), "--kind", "surface"]
    assert main([*cmd, "--quality", "45"]) == 0
    assert main(["decode", str(tmp_path / "s.wcb"), str(tmp_path / "s2.npy")]) == 0
    assert np.load(tmp_path / "s2.npy").shape == (12, 14)


def test_errors_are_messages_not_tracebacks(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["encode", str(tmp_path / "missing.png"), str(tmp_path / "x.wcb")]) == 1
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "bad.wcb").write_bytes(b"WVB garbage")
    assert main(["inspect", str(tmp_path / "bad.wcb")]) == 1
    assert "wavecore: error:" in capsys.readouterr().err
    bundle = tmp_path / "ok.wcb"
    assert main(["encode", str(images / "img0.png"), str(bundle)]) == 0
    assert main(["decode", str(bundle), str(tmp_path / "out.jpg")]) == 1
    assert ".png" in capsys.readouterr().err
    assert main(["encode", str(images / "img0.png"), str(bundle), "--tolerance", "0.1"]) == 1
    assert "--tolerance does not apply to an image" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:
        main(["encode", "a", "b", "--keep", "2"])
    assert usage.value.code == 2
    with pytest.raises(SystemExit):
        main(["encode", "a", "b", "--keep", "0.5", "--quality", "30"])


def test_nothing_is_written_over_an_input_or_an_earlier_output(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `encode img.png img.png` replaced the picture with its bundle
    picture = images / "img0.png"
    before = picture.read_bytes()
    assert main(["encode", str(picture), str(picture)]) == 1
    assert "is the input itself" in capsys.readouterr().err
    assert picture.read_bytes() == before
    # a.png and a.jpg in one folder both made out/a.wcb, the second over the first
    folder = tmp_path / "same-stem"
    folder.mkdir()
    (folder / "a.png").write_bytes(image_file(test_image((20, 24), seed=1)))
    (folder / "a.jpg").write_bytes(image_file(test_image((20, 24), seed=2), "JPEG"))
    assert main(["encode", str(folder), str(tmp_path / "out")]) == 1
    assert "is also the output of" in capsys.readouterr().out
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["a.wcb"]


def test_bad_files_in_a_batch_are_rows_not_tracebacks(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (images / "empty.npy").write_bytes(b"")  # EOFError from numpy
    (images / "x\x1b]0;title\x07.png").write_bytes(image_file(test_image((20, 24))))
    assert main(["encode", str(images), str(tmp_path / "out"), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "empty.npy" in out and "ends too soon" in out and "4 of 5 done" in out
    assert "\x1b" not in out and "x\\x1b]0;title\\x07.png" in out  # shown escaped
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 200_000 + "]" * 200_000)
    assert main(["encode", str(deep), str(tmp_path / "deep.wcb")]) == 1
    assert "nested too deeply" in capsys.readouterr().err
    closed = tmp_path / "closed.json"
    closed.write_text('{"points": [[0, 0], [1, 0], [1, 1], [0, 1]], "closed": "false"}')
    assert main(["encode", str(closed), str(tmp_path / "closed.wcb")]) == 1
    assert "'closed' must be true or false" in capsys.readouterr().err


def test_console_script_runs(tmp_path: Path, images: Path) -> None:
    script = shutil.which("wavecore", path=str(Path(sys.executable).parent))
    command = [script] if script else [sys.executable, "-m", "service.cli"]
    bundle = tmp_path / "p.wcb"
    subprocess.run([*command, "encode", str(images / "img2.png"), str(bundle), "-q"], check=True)
    result = subprocess.run(
        [*command, "decode", str(bundle), str(tmp_path / "p.npy"), "-q"], capture_output=True
    )
    assert result.returncode == 0, result.stderr
    arr = np.load(io.BytesIO((tmp_path / "p.npy").read_bytes()))
    assert arr.shape == (42, 52)


def test_a_bad_setting_is_one_line_naming_the_variable(
    tmp_path: Path,
    images: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv("WAVECORE_MAX_PIXELS", "lots")
    # commands that do not read the settings are not stopped by them
    np.save(tmp_path / "g.npy", np.random.default_rng(0).random((12, 14)))
    cmd = ["encode", str(tmp_path / "g.npy"), str(tmp_path / "g.wcb"), "--kind", "surface", "-q"]
    assert main(cmd) == 0
    assert main(["inspect", str(tmp_path / "g.wcb")]) == 0
    capsys.readouterr()
    # reading an image file needs WAVECORE_MAX_PIXELS
    assert main(["encode", str(images / "img0.png"), str(tmp_path / "x.wcb")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "WAVECORE_MAX_PIXELS='lots'" in err
    monkeypatch.setenv("WAVECORE_PORT", "-3")
    assert main(["serve"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "WAVECORE_PORT" in err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--workers", "0"], "workers must be a whole number"),  # uvicorn took it as 1
        (["--port", "70000"], "port must be from 0 to 65535"),  # refused after the warm-up
        (["--port", "-1"], "port must be from 0 to 65535"),
    ],
)
def test_serve_refuses_bad_ports_and_worker_counts_before_it_warms_up(
    option: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["serve", *option]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "warm-up" not in err


def test_bundles_are_written_as_wcb_and_wvb_is_read_too(
    tmp_path: Path, images: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bundles"
    assert main(["encode", str(images), str(out), "-q"]) == 0
    assert {p.suffix for p in out.iterdir()} == {".wcb"}
    golden = Path(__file__).resolve().parents[1] / "golden"
    for name in ("image_grey_u8_lossy.wvb", "curve_open_tolerance.wvb"):
        shutil.copy(golden / name, tmp_path / name)
    capsys.readouterr()
    assert main(["inspect", str(tmp_path / "*.wvb")]) == 0
    assert "2 of 2 done" in capsys.readouterr().out
    assert main(["decode", str(tmp_path / "image_grey_u8_lossy.wvb"), str(tmp_path / "g.npy")]) == 0
    expected = np.load(golden / "image_grey_u8_lossy.npy")
    assert np.array_equal(np.load(tmp_path / "g.npy"), expected)


def _numba_cache_state() -> dict[str, tuple[int, int]]:
    """Name -> (size, mtime) of numba's cache files (next to wavecore's sources by default)."""
    import wavecore

    root = Path(os.environ.get("NUMBA_CACHE_DIR") or Path(wavecore.__file__).parent)
    return {
        str(path): (path.stat().st_size, path.stat().st_mtime_ns)
        for pattern in ("*.nbi", "*.nbc")
        for path in root.rglob(pattern)
    }


@pytest.mark.long
def test_serve_warms_up_before_it_is_ready_and_answers_the_first_request_quickly(
    tmp_path: Path,
) -> None:
    """``wavecore serve`` logs its warm-up before uvicorn's "startup complete"; the first
    encode after that compiles nothing."""
    import socket

    import httpx

    script = shutil.which("wavecore", path=str(Path(sys.executable).parent))
    assert script, "the wavecore console script is not installed in this venv"
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = int(sock.getsockname()[1])
    log = tmp_path / "serve.log"
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [script, "serve", "--port", str(port)], stdout=out, stderr=subprocess.STDOUT
        )
    try:
        deadline = time.monotonic() + 600
        while "Application startup complete" not in log.read_text():
            assert proc.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.2)
        text = log.read_text()
        assert "Warming up" in text and "warm-up [1/" in text and "warm-up done" in text
        assert text.index("warm-up done") < text.index("Application startup complete")
        picture = image_file(test_image((512, 512, 3), seed=3))
        compiled_before = _numba_cache_state()
        start = time.perf_counter()
        r = httpx.post(
            f"http://127.0.0.1:{port}/v1/images/encode",
            files={"file": ("p.png", picture)},
            data={"bpp": "1"},
            timeout=60,
        )
        first = time.perf_counter() - start
        assert r.status_code == 200, r.text
        # Nothing was compiled for the request: numba's cache files are as the warm-up left
        # them (the 2 s target itself is a benchmark, benchmarks/first_run.py --serve; a wall
        # clock bound here would fail on a busy machine).
        compiled_after = _numba_cache_state()
        changed = {
            k
            for k in compiled_before.keys() | compiled_after.keys()
            if compiled_before.get(k) != compiled_after.get(k)
        }
        assert not changed, f"the first request compiled: {sorted(changed)}"
        assert first <= 30.0, f"the first request took {first:.2f} s"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.mark.long
def test_core_install_runs_the_library_commands_and_names_the_extra(tmp_path: Path) -> None:
    """``pip install .`` without extras: no top-level ``service`` package, ``wavecore --help``
    and the .json/.npy commands work, image files and ``serve`` are one line naming the extra."""
    root = Path(__file__).resolve().parents[2]
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    install = subprocess.run(
        [str(python), "-m", "pip", "install", "-q", str(root)], capture_output=True, text=True
    )
    assert install.returncode == 0, install.stderr
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    installed = {p.name for p in Path(site).iterdir()}
    assert "wavecore_service" in installed and "service" not in installed
    assert "fastapi" not in installed and "PIL" not in installed
    wavecore_cmd = str(venv / "bin" / "wavecore")

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([wavecore_cmd, *args], capture_output=True, text=True, cwd=tmp_path)

    assert run("--help").returncode == 0
    (tmp_path / "c.json").write_text(json.dumps({"points": circle(40), "closed": True}))
    assert run("encode", "c.json", "c.wcb", "-q").returncode == 0
    assert run("decode", "c.wcb", "c2.json", "-q").returncode == 0
    assert len(json.loads((tmp_path / "c2.json").read_text())["points"]) == 40
    inspected = run("inspect", "c.wcb")
    assert inspected.returncode == 0 and "curve 40×2" in inspected.stdout
    np.save(tmp_path / "g.npy", np.random.default_rng(1).random((20, 16)))
    assert run("encode", "g.npy", "g.wcb", "--kind", "surface", "-q").returncode == 0
    (tmp_path / "p.png").write_bytes(image_file(test_image((20, 24), seed=1)))
    for result in (run("encode", "p.png", "p.wcb"), run("serve")):
        assert result.returncode == 1
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "pip install 'wavecore[service]'" in lines[0], result.stderr


def test_wavelet_defaults_per_kind(tmp_path: Path, images: Path) -> None:
    # Images default to auto, cdf97 on photographs (issue 12), curves keep bspline2; --wavelet
    # overrides either.
    bundle = tmp_path / "a.wcb"
    assert main(["encode", str(images / "img0.png"), str(bundle), "-q"]) == 0
    assert wavecore.inspect(bundle.read_bytes())["wavelet"] == "cdf97"
    cmd = ["encode", str(images / "img0.png"), str(bundle), "-q", "--wavelet", "bspline2"]
    assert main(cmd) == 0
    assert wavecore.inspect(bundle.read_bytes())["wavelet"] == "bspline2"
    (tmp_path / "c.json").write_text(json.dumps({"points": circle(48), "closed": True}))
    assert main(["encode", str(tmp_path / "c.json"), str(tmp_path / "c.wcb"), "-q"]) == 0
    assert wavecore.inspect((tmp_path / "c.wcb").read_bytes())["wavelet"] == "bspline2"
