"""The ``wavecore`` command line, called as ``main([...])`` and once as a real process."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
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


def test_lossless_is_exact(tmp_path: Path, images: Path) -> None:
    bundle = tmp_path / "exact.wcb"
    assert main(["encode", str(images / "img1.png"), str(bundle), "--lossless"]) == 0
    assert main(["decode", str(bundle), str(tmp_path / "exact.png")]) == 0
    original = np.asarray(Image.open(images / "img1.png"))
    assert np.array_equal(np.asarray(Image.open(tmp_path / "exact.png")), original)


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
    with pytest.raises(SystemExit) as usage:
        main(["encode", "a", "b", "--keep", "2"])
    assert usage.value.code == 2
    with pytest.raises(SystemExit):
        main(["encode", "a", "b", "--keep", "0.5", "--quality", "30"])


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
