"""The upload page (``GET /``) in real headless Chromium against the real server process."""

from __future__ import annotations

import base64
import hashlib
import io
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

# Long (about a minute): not in the default run; `pytest -m long` and CI's .ci/run run them.
pytestmark = [pytest.mark.browser, pytest.mark.long]

PHONE = {"width": 390, "height": 844}


@pytest.fixture(scope="module")
def astronaut_png(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 256 × 256 RGB photograph (scikit-image's astronaut), as a PNG file."""
    from PIL import Image
    from skimage import data

    image = Image.fromarray(data.astronaut()).resize((256, 256), Image.Resampling.LANCZOS)
    path = tmp_path_factory.mktemp("images") / "astronaut.png"
    image.save(path)
    return path


def image_bytes(page: Any, selector: str) -> bytes:
    """The bytes behind an ``<img>``'s blob URL, read inside the page."""
    encoded = page.evaluate(
        """async (selector) => {
            const img = document.querySelector(selector);
            const blob = await (await fetch(img.src)).blob();
            const bytes = new Uint8Array(await blob.arrayBuffer());
            let text = "";
            for (const b of bytes) text += String.fromCharCode(b);
            return btoa(text);
        }""",
        selector,
    )
    return base64.b64decode(encoded)


def png_pixels(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"), dtype=np.float64)


def figure(page: Any, name: str) -> str:
    return str(page.inner_text(f"#fig-{name}")).strip()


def number(text: str) -> float:
    match = re.search(r"-?\d+(\.\d+)?", text)
    assert match, f"no number in {text!r}"
    return float(match.group())


def bundles_shown(page: Any) -> int:
    return int(page.evaluate("Number(document.body.dataset.bundles || 0)"))


def wait_for_bundle(page: Any, number: int) -> None:
    """Waits until the page shows its ``number``-th bundle: reconstruction and coarse view."""
    page.wait_for_selector(f"#img-recon[data-bundle='{number}']")
    page.wait_for_selector(f"#img-coarse[data-bundle='{number}']")


def upload_image(page: Any, path: Path) -> None:
    before = bundles_shown(page)
    page.set_input_files("#image-file", str(path))
    wait_for_bundle(page, before + 1)


def move_keep_slider(page: Any, value: int) -> float:
    """Moves the keep slider as a user would (focus, arrow keys), returns the keep it shows."""
    keep = float(page.evaluate("(v) => window.wavecore.sliderToKeep(v)", value))
    page.focus("#keep-slider")
    current = int(page.input_value("#keep-slider"))
    key = "ArrowLeft" if value < current else "ArrowRight"
    for _ in range(abs(current - value)):
        page.keyboard.press(key)
    page.wait_for_selector(f"#img-recon[data-keep='{keep}']")
    return keep


def test_page_has_labelled_controls_and_loads_nothing_from_elsewhere(page: Any, artifacts: Path):
    assert "wavecore" in page.title()
    unlabelled = page.evaluate(
        """() => [...document.querySelectorAll('input, select')].filter((el) =>
            !(el.labels && el.labels.length) && !el.getAttribute('aria-label')
        ).map((el) => el.id || el.name)"""
    )
    assert unlabelled == []
    # The keyboard reaches the mode switch and the file chooser.
    reached = []
    for _ in range(8):
        page.keyboard.press("Tab")
        reached.append(page.evaluate("document.activeElement.id || document.activeElement.name"))
    assert "mode" in reached
    assert "image-file" in reached
    assert "sample-image" in reached
    page.screenshot(path=artifacts / "empty-desktop.png", full_page=True)


def test_upload_image_shows_figures_and_slider_redecodes_the_same_bundle(
    page: Any, astronaut_png: Path, artifacts: Path
):
    encode_requests: list[str] = []
    page.on(
        "request",
        lambda r: encode_requests.append(r.url) if "/encode" in r.url else None,
    )
    upload_image(page, astronaut_png)

    bundle_bytes = number(figure(page, "bytes"))
    ratio = number(figure(page, "ratio"))
    bpp = number(figure(page, "bpp"))
    psnr_full = number(figure(page, "psnr"))
    assert bundle_bytes > 0
    assert ratio > 1, "a lossy bundle is smaller than the raw pixels"
    assert 0 < bpp < 24
    assert psnr_full > 25
    assert page.get_attribute("#img-original", "alt")
    assert page.get_attribute("#img-recon", "alt")
    full = image_bytes(page, "#img-recon")
    coarse = png_pixels(image_bytes(page, "#img-coarse"))
    level = int(page.input_value("#level-slider"))
    assert 256 / 2**level <= coarse.shape[0] <= 256 / 2**level + 4
    page.screenshot(path=artifacts / "image-desktop.png", full_page=True)

    keep = move_keep_slider(page, 30)
    assert keep < 0.02
    low = image_bytes(page, "#img-recon")
    assert hashlib.sha256(low).digest() != hashlib.sha256(full).digest()
    psnr_low = number(figure(page, "psnr"))
    assert psnr_low < psnr_full, "fewer details, lower PSNR"
    # Measured independently of the page: the PSNR it shows is the PSNR of what it shows.
    original = png_pixels(astronaut_png.read_bytes())
    mse = float(np.mean((png_pixels(low) - original) ** 2))
    assert 10 * np.log10(255**2 / mse) == pytest.approx(psnr_low, abs=0.02)
    assert len(encode_requests) == 1, "the slider never re-uploads"
    page.screenshot(path=artifacts / "image-keep-low.png", full_page=True)


def test_haar_against_bspline_at_the_same_keep(page: Any, astronaut_png: Path, artifacts: Path):
    upload_image(page, astronaut_png)
    keep = move_keep_slider(page, 30)
    page.click("#compare-run")
    page.wait_for_selector(f"#cmp-haar[data-keep='{keep}']")
    page.wait_for_selector(f"#cmp-bspline2[data-keep='{keep}']")
    # Photographs are coded with the default, auto, which chooses cdf97; the comparison shows
    # cdf97 as well.
    assert figure(page, "wavelet") == "cdf97"
    page.wait_for_selector(f"#cmp-cdf97[data-keep='{keep}']")
    smooth = png_pixels(image_bytes(page, "#cmp-bspline2"))
    blocky = png_pixels(image_bytes(page, "#cmp-haar"))

    # Haar's reconstruction is piecewise constant: far more neighbours share exactly one value.
    def flat_share(img: np.ndarray) -> float:
        return float(np.mean(np.all(img[:, 1:] == img[:, :-1], axis=-1)))

    assert flat_share(blocky) > 2 * flat_share(smooth)
    page.screenshot(path=artifacts / "compare-haar.png", full_page=True)

    # Switching the wavelet itself re-encodes with Haar.
    before = bundles_shown(page)
    page.select_option("#wavelet", "haar")
    wait_for_bundle(page, before + 1)
    assert figure(page, "wavelet") == "haar"


def draw(page: Any, selector: str, curve: Any, steps: int = 120) -> None:
    """Draws ``curve(t)`` (t in [0, 1], in fractions of the pad) with mouse events."""
    box = page.locator(selector).bounding_box()

    def at(t: float) -> tuple[float, float]:
        u, v = curve(t)
        return box["x"] + u * box["width"], box["y"] + v * box["height"]

    page.mouse.move(*at(0.0))
    page.mouse.down()
    for i in range(1, steps + 1):
        page.mouse.move(*at(i / steps))
    page.mouse.up()


def wiggle(t: float) -> tuple[float, float]:
    return 0.1 + 0.8 * t, 0.5 + 0.3 * np.sin(6 * np.pi * t) * (1 - t)


def test_draw_a_curve_and_see_its_coarse_curve(page: Any, artifacts: Path):
    page.click("label:has(input[name=mode][value=curve])")
    draw(page, "#curve-pad", wiggle)
    page.wait_for_selector("#curve-plot[data-level]")
    page.wait_for_selector("#curve-plot[data-keep]")
    coarse = int(page.get_attribute("#curve-plot", "data-coarse-points"))
    recon = int(page.get_attribute("#curve-plot", "data-recon-points"))
    assert 2 <= coarse < recon
    assert page.locator("#curve-plot path.coarse").count() == 1
    assert page.locator("#curve-plot path.recon").count() == 1
    assert number(figure(page, "maxerr")) >= 0
    page.screenshot(path=artifacts / "curve-desktop.png", full_page=True)


def path_points(page: Any, selector: str) -> np.ndarray:
    """The points of an SVG path's ``d`` (``M x y L x y …``)."""
    d = str(page.get_attribute(selector, "d"))
    return np.array(re.findall(r"(-?[\d.]+) (-?[\d.]+)", d), dtype=np.float64)


def test_haar_against_bspline_on_a_drawn_curve(page: Any, artifacts: Path):
    page.click("label:has(input[name=mode][value=curve])")
    assert page.input_value("#wavelet") == "bspline2", "curves keep the paper's filter"
    draw(page, "#curve-pad", wiggle)
    page.wait_for_selector("#curve-plot[data-keep]")
    keep = float(page.evaluate("(v) => window.wavecore.sliderToKeep(v)", 20))
    page.focus("#keep-slider")
    for _ in range(int(page.input_value("#keep-slider")) - 20):
        page.keyboard.press("ArrowLeft")
    page.wait_for_selector(f"#curve-plot[data-keep='{keep}']")
    page.click("#compare-run")
    page.wait_for_selector(f"#cmp-haar-plot[data-keep='{keep}']")
    page.wait_for_selector(f"#cmp-bspline2-plot[data-keep='{keep}']")
    assert page.is_hidden("#cmp-haar") and page.is_visible("#cmp-haar-plot")
    assert "max error" in page.inner_text("#cmp-haar-tag")

    # Haar's curve, its details mostly dropped, is a staircase: many consecutive points coincide.
    def repeated_share(points: np.ndarray) -> float:
        return float(np.mean(np.all(np.abs(np.diff(points, axis=0)) < 1e-6, axis=1)))

    smooth = path_points(page, "#cmp-bspline2-plot path.recon")
    steps = path_points(page, "#cmp-haar-plot path.recon")
    assert len(smooth) == len(steps) > 20
    assert repeated_share(steps) > 0.3 > 3 * repeated_share(smooth)
    page.screenshot(path=artifacts / "compare-haar-curve.png", full_page=True)

    # The wavelet choice applies to curves too: choosing Haar re-encodes the curve with it.
    before = bundles_shown(page)
    page.select_option("#wavelet", "haar")
    page.wait_for_selector(f"#curve-plot[data-bundle='{before + 1}']")
    assert figure(page, "wavelet") == "haar"


def test_corrupt_bundle_shows_a_readable_error_next_to_the_bundle_input(page: Any, artifacts: Path):
    page.click("label:has(input[name=mode][value=bundle])")
    junk = np.random.default_rng(6).integers(0, 256, 300, dtype=np.uint8).tobytes()
    page.set_input_files(
        "#bundle-file",
        files=[{"name": "broken.wcb", "mimeType": "application/octet-stream", "buffer": junk}],
    )
    error = page.locator("#bundle-file-error")
    error.wait_for(state="visible")
    assert "bundle" in error.inner_text().lower()
    assert page.get_attribute("#bundle-file", "aria-invalid") == "true"
    page.screenshot(path=artifacts / "bundle-error.png", full_page=True)
    page.problems.clear()


def test_bad_parameter_error_sits_next_to_the_target(page: Any, astronaut_png: Path):
    page.click("label:has(input[name=target][value=keep])")
    page.fill("#keep", "2")
    page.set_input_files("#image-file", str(astronaut_png))
    error = page.locator("#target-error")
    error.wait_for(state="visible")
    assert "keep" in error.inner_text().lower()
    page.problems.clear()


def test_download_bundle_decodes_and_reopens(page: Any, astronaut_png: Path, tmp_path: Path):
    import wavecore

    upload_image(page, astronaut_png)
    with page.expect_download() as info:
        page.click("#download")
    saved = tmp_path / "download.wcb"
    info.value.save_as(saved)
    decoded = wavecore.decode(saved.read_bytes())
    assert decoded.shape == (256, 256, 3)
    assert decoded.dtype == np.uint8
    shown = number(figure(page, "bytes"))
    assert saved.stat().st_size == pytest.approx(shown * 1024, rel=0.06)

    # Upload the downloaded bundle: it reconstructs to what the page showed before.
    page.click("label:has(input[name=mode][value=bundle])")
    before = bundles_shown(page)
    page.set_input_files("#bundle-file", str(saved))
    wait_for_bundle(page, before + 1)
    shown_pixels = png_pixels(image_bytes(page, "#img-recon"))
    assert np.array_equal(shown_pixels, decoded.astype(np.float64))


def test_phone_width_has_no_sideways_scrolling(page: Any, astronaut_png: Path, artifacts: Path):
    page.set_viewport_size(PHONE)
    upload_image(page, astronaut_png)
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= PHONE["width"]
    page.screenshot(path=artifacts / "image-phone.png", full_page=True)


def test_details_of_a_drawn_curve_go_onto_a_second_base_curve(page: Any, artifacts: Path):
    page.click("label:has(input[name=mode][value=curve])")
    draw(page, "#curve-pad", wiggle)
    page.wait_for_selector("#curve-plot[data-bundle='1']")
    source_points = int(page.get_attribute("#curve-plot", "data-recon-points"))
    page.locator("#transfer").scroll_into_view_if_needed()
    # A smooth arc: the paper's figure 1, a new coarse shape under the same details.
    draw(page, "#transfer-pad", lambda t: (0.1 + 0.8 * t, 0.8 - 0.6 * np.sin(np.pi * t)), 60)
    page.wait_for_selector("#transfer-pad[data-points]:not([data-points='0'])")
    assert int(page.get_attribute("#transfer-pad", "data-points")) == source_points
    assert page.locator("#transfer-error").is_hidden()
    page.screenshot(path=artifacts / "curve-transfer.png", full_page=True)


def test_large_image_shows_progress_and_the_page_stays_responsive(
    page: Any, astronaut_png: Path, tmp_path: Path
):
    from PIL import Image

    big = tmp_path / "big.png"
    Image.open(astronaut_png).resize((1024, 1024), Image.Resampling.BICUBIC).save(big)
    # One encode (keep) rather than a quality search: the test is about the page, not speed.
    page.click("label:has(input[name=target][value=keep])")
    before = bundles_shown(page)
    page.set_input_files("#image-file", str(big))
    page.locator("#progress").wait_for(state="visible")
    assert page.is_disabled("#encode")
    # While the server works the page still answers at once (no long task on the main thread).
    lag = page.evaluate(
        """() => new Promise((resolve) => {
            const start = performance.now();
            setTimeout(() => resolve(performance.now() - start), 0);
        })"""
    )
    assert lag < 250
    page.set_default_timeout(180_000)
    wait_for_bundle(page, before + 1)
    assert page.locator("#progress").is_hidden()


def test_curve_json_file_is_encoded_in_its_own_coordinates(page: Any, tmp_path: Path):
    import json

    import wavecore

    t = np.linspace(0, 2 * np.pi, 150, endpoint=False)
    circle = np.stack([3 + np.cos(t) + 0.05 * np.cos(9 * t), -2 + np.sin(t)], axis=1)
    path = tmp_path / "circle.json"
    path.write_text(json.dumps({"points": circle.tolist(), "closed": True}))
    page.click("label:has(input[name=mode][value=curve])")
    page.set_input_files("#curve-file", str(path))
    page.wait_for_selector("#curve-plot[data-bundle='1']")
    assert page.is_checked("#curve-closed")
    tolerance = float(page.input_value("#tolerance"))
    with page.expect_download() as info:
        page.click("#download")
    decoded = wavecore.decode(Path(info.value.path()).read_bytes())
    assert decoded.shape == circle.shape
    assert np.max(np.linalg.norm(decoded - circle, axis=1)) <= tolerance


def test_a_text_file_named_png_gets_a_message_next_to_the_file_input(page: Any):
    page.set_input_files(
        "#image-file",
        files=[{"name": "notes.png", "mimeType": "image/png", "buffer": b"just some text\n" * 20}],
    )
    error = page.locator("#image-file-error")
    error.wait_for(state="visible")
    assert "415" not in error.inner_text()  # a sentence, not a status code
    assert len(error.inner_text()) > 20
    assert page.locator("#encode-error").is_hidden()
    page.problems.clear()


def test_an_upload_over_the_limit_gets_a_message_next_to_the_file_input(
    open_tab: Any, small_limit_server: str, astronaut_png: Path, artifacts: Path
):
    page = open_tab(small_limit_server)
    page.set_input_files("#image-file", str(astronaut_png))  # about 110 kB > 100 kB
    error = page.locator("#image-file-error")
    error.wait_for(state="visible")
    assert "large" in error.inner_text().lower()
    assert page.locator("#progress").is_hidden()
    page.screenshot(path=artifacts / "upload-too-large.png")
    page.problems.clear()


def test_drop_an_image_on_the_drop_zone(page: Any):
    # What a drag from the desktop delivers: a drop event whose DataTransfer holds a file.
    page.evaluate(
        """async () => {
            const canvas = new OffscreenCanvas(96, 64);
            const ctx = canvas.getContext("2d");
            ctx.fillStyle = "#3a5bd9";
            ctx.fillRect(0, 0, 96, 64);
            ctx.fillStyle = "#ffd18a";
            ctx.fillRect(20, 10, 30, 40);
            const blob = await canvas.convertToBlob({ type: "image/png" });
            const transfer = new DataTransfer();
            transfer.items.add(new File([blob], "dropped.png", { type: "image/png" }));
            const zone = document.getElementById("image-drop");
            const options = { dataTransfer: transfer, bubbles: true };
            zone.dispatchEvent(new DragEvent("dragover", options));
            zone.dispatchEvent(new DragEvent("drop", options));
        }"""
    )
    wait_for_bundle(page, 1)
    assert "dropped.png" in page.inner_text("#image-name")
    # The default, auto, codes this two-tone graphic with Haar, and the file name says so.
    assert page.get_attribute("#download", "download") == "dropped-haar.wcb"


def test_levels_out_of_range_are_caught_before_any_upload(page: Any, astronaut_png: Path):
    uploads: list[str] = []
    page.on("request", lambda r: uploads.append(r.url) if "/encode" in r.url else None)
    page.fill("#level", "40")
    page.set_input_files("#image-file", str(astronaut_png))
    error = page.locator("#level-error")
    error.wait_for(state="visible")
    assert "40" in error.inner_text()
    assert page.get_attribute("#level", "aria-invalid") == "true"
    assert uploads == []


def test_keyboard_only_sample_image_then_slider(page: Any):
    def tab_to(element_id: str) -> None:
        for _ in range(40):
            page.keyboard.press("Tab")
            if page.evaluate("document.activeElement.id") == element_id:
                # A visible focus ring on whatever has the focus.
                shadow = page.evaluate("getComputedStyle(document.activeElement).boxShadow")
                outline = page.evaluate("getComputedStyle(document.activeElement).outlineStyle")
                assert shadow != "none" or outline != "none"
                return
        raise AssertionError(f"Tab never reached #{element_id}")

    tab_to("sample-image")
    page.keyboard.press("Enter")
    wait_for_bundle(page, 1)
    tab_to("keep-slider")
    for _ in range(40):
        page.keyboard.press("ArrowLeft")
    keep = float(page.evaluate("(v) => window.wavecore.sliderToKeep(v)", 60))
    page.wait_for_selector(f"#img-recon[data-keep='{keep}']")
    missing_alt = page.evaluate(
        "[...document.querySelectorAll('img[src]')].filter((i) => !i.alt.trim()).length"
    )
    assert missing_alt == 0


def test_lossless_upload_is_exact_and_offers_coarser_levels(page: Any, astronaut_png: Path):
    """The default lossless coder codes no level (or one); the page still offers the coarser
    previews that decode lifts from the decoded picture, and names how it was coded."""
    page.check("input[name='target'][value='lossless']")
    upload_image(page, astronaut_png)
    assert figure(page, "wavelet").startswith("lossless (")
    original = png_pixels(astronaut_png.read_bytes())
    assert np.array_equal(png_pixels(image_bytes(page, "#img-recon")), original)
    assert int(page.get_attribute("#level-slider", "max")) == 5
    level = int(page.input_value("#level-slider"))
    assert level == 3
    coarse = png_pixels(image_bytes(page, "#img-coarse"))
    assert coarse.shape[0] == -(-original.shape[0] // 2**level)
