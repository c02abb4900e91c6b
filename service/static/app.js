// wavecore upload page. Plain JavaScript, no build step, no third-party code.
//
// The flow: an input (image file, curve, or bundle) is encoded once by the server into a bundle;
// everything after that (the keep slider, the coarse level, the wavelet comparison) re-decodes
// that same bundle through POST /v1/bundles/reconstruct, so nothing is uploaded twice.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const SVG_NS = "http://www.w3.org/2000/svg";
  const BUNDLE_TYPE = "application/vnd.wavecore.bundle";
  const PAD_W = 400;
  const PAD_H = 300;
  // Client-side PSNR reads every pixel of two images; past this it would cost more than it tells.
  const MAX_PSNR_PIXELS = 16e6;

  const state = {
    mode: "image",
    kind: null, // "image" or "curve": what the current bundle holds
    bundle: null, // Blob
    bundleName: "bundle.wcb",
    info: null, // POST /v1/bundles/inspect
    figures: {}, // from the encode response headers
    source: null, // the image File/Blob or the curve {points, closed} that was encoded
    originalPixels: null, // Promise<ImageData|null> for client-side PSNR
    curve: null, // {points, closed} (y up) of the encoded curve
    drawn: [], // points drawn on the pad (pad coordinates, y down)
    base: [], // the second curve for the figure-1 transfer
    compare: null, // {bspline2: Blob, haar: Blob, cdf97: Blob (images only)}
    waveletChosen: false, // the user picked a wavelet: mode switches keep it
    urls: {}, // object URLs per <img>, revoked when replaced
    seq: { recon: 0, coarse: 0, compare: 0, encode: 0, transfer: 0 },
    xhr: {}, // in-flight requests per purpose, aborted when superseded
    loaded: 0, // bundles shown so far; views carry the number of the bundle they show
  };

  // ---------------------------------------------------------------- HTTP

  class ApiError extends Error {
    constructor(status, title, detail, type, fields) {
      super(detail || title);
      this.status = status;
      this.title = title;
      this.detail = detail;
      this.type = type;
      this.fields = fields || [];
    }
  }

  // XMLHttpRequest rather than fetch: it reports upload progress, which a large image needs.
  function request(purpose, method, url, body, options = {}) {
    if (state.xhr[purpose]) state.xhr[purpose].abort();
    return new Promise((resolve, reject) => {
      const xhr = new XMLHttpRequest();
      state.xhr[purpose] = xhr;
      xhr.open(method, url);
      xhr.responseType = "blob";
      for (const [name, value] of Object.entries(options.headers || {})) {
        xhr.setRequestHeader(name, value);
      }
      if (options.onUpload) {
        xhr.upload.onprogress = (event) => {
          if (event.lengthComputable) options.onUpload(event.loaded / event.total);
        };
        xhr.upload.onload = () => options.onUpload(1);
      }
      xhr.onload = async () => {
        if (state.xhr[purpose] === xhr) delete state.xhr[purpose];
        if (xhr.status >= 200 && xhr.status < 300) {
          resolve({ blob: xhr.response, header: (name) => xhr.getResponseHeader(name) });
        } else {
          reject(await problemFrom(xhr));
        }
      };
      xhr.onerror = () => {
        if (state.xhr[purpose] === xhr) delete state.xhr[purpose];
        reject(new ApiError(0, "Network error", "The server could not be reached. Is it still running?"));
      };
      xhr.onabort = () => reject(new DOMException("superseded", "AbortError"));
      xhr.send(body);
    });
  }

  // Turns any error response into a readable message; problem+json (RFC 9457) is the normal case.
  async function problemFrom(xhr) {
    let text = "";
    try {
      text = await xhr.response.text();
    } catch {
      /* an empty body is handled below */
    }
    let data = null;
    try {
      data = JSON.parse(text);
    } catch {
      /* not JSON */
    }
    if (data && typeof data === "object") {
      if (Array.isArray(data.detail)) {
        // FastAPI's own validation format: [{loc: [...], msg}, ...]
        const fields = data.detail.map((e) => (e.loc || []).slice(-1)[0]).filter(Boolean);
        const detail = data.detail.map((e) => `${(e.loc || []).slice(1).join(".")}: ${e.msg}`).join("; ");
        return new ApiError(xhr.status, "Invalid input", detail, "", fields);
      }
      const fields = Array.isArray(data.errors)
        ? data.errors.map((e) => (e.loc || [e.field || e.name]).slice(-1)[0]).filter(Boolean)
        : [];
      return new ApiError(
        xhr.status,
        data.title || xhr.statusText || `HTTP ${xhr.status}`,
        typeof data.detail === "string" ? data.detail : "",
        data.type || "",
        fields,
      );
    }
    const short = text && text.length < 300 ? text : "";
    return new ApiError(xhr.status, xhr.statusText || `HTTP ${xhr.status}`, short);
  }

  function errorText(err) {
    if (err instanceof ApiError) {
      if (err.detail && err.title && !err.detail.toLowerCase().startsWith(err.title.toLowerCase())) {
        return `${err.title}: ${err.detail}`;
      }
      return err.detail || err.title;
    }
    return String(err && err.message ? err.message : err);
  }

  const isAbort = (err) => err && err.name === "AbortError";

  // ---------------------------------------------------------------- errors next to controls

  function showError(id, err) {
    const el = $(id);
    el.textContent = typeof err === "string" ? err : errorText(err);
    el.hidden = false;
    const control = el.dataset.for ? $(el.dataset.for) : null;
    if (control) control.setAttribute("aria-invalid", "true");
  }

  function clearErrors(...ids) {
    for (const id of ids) {
      const el = $(id);
      el.hidden = true;
      el.textContent = "";
    }
    for (const el of document.querySelectorAll("[aria-invalid]")) el.removeAttribute("aria-invalid");
  }

  const ENCODE_ERRORS = [
    "image-file-error",
    "curve-file-error",
    "wavelet-error",
    "level-error",
    "target-error",
    "encode-error",
  ];

  // Which control caused an encode error: the field the server names, else the status says.
  function encodeErrorPlace(err) {
    const named = (name) =>
      err.fields.includes(name) || new RegExp(`\\b${name}\\b`, "i").test(err.detail || "");
    const fileError = state.mode === "curve" ? "curve-file-error" : "image-file-error";
    if (err.status === 413 || err.status === 415) return fileError;
    if (["keep", "quality", "bpp", "tolerance", "lossless"].some(named)) return "target-error";
    if (named("level") || named("levels")) return "level-error";
    if (named("wavelet")) return "wavelet-error";
    if (named("file") || named("points") || named("image")) return fileError;
    return "encode-error";
  }

  // ---------------------------------------------------------------- settings

  const target = () => document.querySelector('input[name="target"]:checked').value;

  function readSettings() {
    const settings = {};
    const level = $("level").value.trim();
    if (level !== "") settings.level = level;
    const chosen = target();
    if (chosen === "lossless") settings.lossless = "true";
    else settings[chosen] = $(chosen).value.trim();
    return settings;
  }

  function showTarget() {
    const chosen = target();
    for (const el of document.querySelectorAll(".target-value")) el.hidden = el.dataset.target !== chosen;
  }

  // Targets that this kind of input does not have fall back to keep.
  function fixTargetForMode() {
    const checked = document.querySelector('input[name="target"]:checked');
    const hiddenNow = checked.closest("label").matches(state.mode === "curve" ? ".image-only" : ".curve-only");
    if (hiddenNow) document.querySelector('input[name="target"][value="keep"]').checked = true;
    showTarget();
  }

  function setMode(mode) {
    // Curves have no quality, bpp or lossless target; images no tolerance: pick one they have.
    if (mode === "curve" && !["keep", "tolerance"].includes(target())) {
      // A tolerance keeps the drawn curve faithful; the keep slider then simplifies it.
      document.querySelector('input[name="target"][value="tolerance"]').checked = true;
    } else if (mode === "image" && target() === "tolerance") {
      document.querySelector('input[name="target"][value="quality"]').checked = true;
    }
    // Each kind starts on its own default wavelet (auto for images, the paper's bspline2 for
    // curves) until the user picks one; curves have no "auto".
    const curveOnAuto = mode === "curve" && $("wavelet").value === "auto";
    if ((!state.waveletChosen || curveOnAuto) && (mode === "image" || mode === "curve")) {
      $("wavelet").value = mode === "curve" ? "bspline2" : "auto";
    }
    state.mode = mode;
    document.body.dataset.mode = mode;
    for (const pane of document.querySelectorAll(".mode-pane")) pane.hidden = pane.dataset.mode !== mode;
    fixTargetForMode();
  }

  // ---------------------------------------------------------------- progress

  let progressTimer = null;

  function startProgress(label) {
    const started = performance.now();
    $("progress").hidden = false;
    $("progress-bar").value = 0;
    $("progress-text").textContent = label;
    $("encode").disabled = true;
    $("results").setAttribute("aria-busy", "true");
    clearInterval(progressTimer);
    progressTimer = setInterval(() => {
      const seconds = (performance.now() - started) / 1000;
      const text = $("progress-text");
      if (seconds >= 2 && text.textContent.startsWith("Compressing")) {
        text.textContent = `Compressing… ${seconds.toFixed(0)} s`;
      }
    }, 500);
    return {
      upload(fraction) {
        if (fraction < 1) {
          $("progress-bar").value = Math.round(fraction * 100);
          $("progress-text").textContent = `Uploading ${Math.round(fraction * 100)} %`;
        } else {
          $("progress-bar").removeAttribute("value"); // indeterminate while the server works
          $("progress-text").textContent = "Compressing…";
        }
      },
    };
  }

  function stopProgress() {
    clearInterval(progressTimer);
    $("progress").hidden = true;
    $("encode").disabled = false;
    $("results").removeAttribute("aria-busy");
  }

  // ---------------------------------------------------------------- formatting

  function formatBytes(n) {
    if (n == null || !Number.isFinite(n)) return "–";
    if (n < 1024) return `${n} B`;
    if (n < 1024 * 1024) return `${(n / 1024).toFixed(n < 10240 ? 1 : 0)} KiB`;
    return `${(n / 1024 / 1024).toFixed(2)} MiB`;
  }

  const formatNumber = (x, digits) => (x == null || !Number.isFinite(Number(x)) ? "–" : Number(x).toFixed(digits));

  function formatPsnr(psnr) {
    if (psnr === Infinity || psnr === "inf" || psnr === null) return "exact";
    return `${formatNumber(psnr, 2)} dB`;
  }

  function formatKeep(keep) {
    if (keep >= 1) return "100 %";
    if (keep <= 0) return "0 %";
    const percent = keep * 100;
    return `${percent >= 10 ? percent.toFixed(0) : percent >= 1 ? percent.toFixed(1) : percent.toFixed(2)} %`;
  }

  // The slider is logarithmic: most of what is interesting happens below 10 %.
  function sliderToKeep(value) {
    const v = Number(value);
    if (v <= 0) return 0;
    if (v >= 100) return 1;
    return Number((10 ** (3 * (v / 100) - 3)).toPrecision(3));
  }

  function keepToSlider(keep) {
    if (keep <= 0) return 0;
    return Math.max(1, Math.min(100, Math.round(((Math.log10(keep) + 3) / 3) * 100)));
  }

  const DTYPE_BYTES = { uint8: 1, int8: 1, uint16: 2, int16: 2, float32: 4, float64: 8, int32: 4, uint32: 4, int64: 8 };

  function rawBytes(info) {
    if (!info || !Array.isArray(info.shape)) return null;
    const count = info.shape.reduce((a, b) => a * b, 1);
    return count * (DTYPE_BYTES[info.dtype] || 8);
  }

  // ---------------------------------------------------------------- images on the page

  function setImage(id, blob) {
    const img = $(id);
    if (state.urls[id]) URL.revokeObjectURL(state.urls[id]);
    const url = URL.createObjectURL(blob);
    state.urls[id] = url;
    return new Promise((resolve) => {
      img.onload = () => resolve(img);
      img.onerror = () => resolve(img);
      img.src = url;
    });
  }

  function clearImage(id) {
    const img = $(id);
    if (state.urls[id]) URL.revokeObjectURL(state.urls[id]);
    delete state.urls[id];
    img.removeAttribute("src");
    delete img.dataset.keep;
    delete img.dataset.level;
    delete img.dataset.bundle;
  }

  function setLoading(id, on) {
    const frame = $(id).closest(".frame");
    if (frame) frame.classList.toggle("loading", on);
  }

  // Decoded off the main thread (createImageBitmap), so a large original does not freeze the page.
  async function pixelsOf(blob) {
    try {
      const bitmap = await createImageBitmap(blob, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
      if (bitmap.width * bitmap.height > MAX_PSNR_PIXELS) return null;
      const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
      const ctx = canvas.getContext("2d", { willReadFrequently: true });
      ctx.drawImage(bitmap, 0, 0);
      bitmap.close();
      return ctx.getImageData(0, 0, canvas.width, canvas.height);
    } catch {
      return null;
    }
  }

  // PSNR at peak 255, counted as the server counts it (wavecore's codec): over the colour
  // channels (one for a grey picture, which the canvas spreads over R, G and B), and over alpha
  // too only when alpha did not come back exactly (an opaque alpha always does).
  function psnr(a, b) {
    if (!a || !b || a.width !== b.width || a.height !== b.height) return null;
    const x = a.data;
    const y = b.data;
    let colour = 0;
    let alpha = 0;
    let grey = true;
    for (let i = 0; i < x.length; i += 4) {
      const d0 = x[i] - y[i];
      const d1 = x[i + 1] - y[i + 1];
      const d2 = x[i + 2] - y[i + 2];
      const d3 = x[i + 3] - y[i + 3];
      colour += d0 * d0 + d1 * d1 + d2 * d2;
      alpha += d3 * d3;
      if (grey && (x[i] !== x[i + 1] || x[i] !== x[i + 2])) grey = false;
    }
    const pixels = x.length / 4;
    // A grey original's three equal channels stand for one: its squared error, counted once.
    const colours = grey ? 1 : 3;
    const sum = (grey ? colour / 3 : colour) + alpha;
    const mse = sum / (pixels * (alpha > 0 ? colours + 1 : colours));
    return mse === 0 ? Infinity : 10 * Math.log10((255 * 255) / mse);
  }

  // ---------------------------------------------------------------- curves

  const clonePoints = (points) => points.map((p) => p.slice());

  // Pad coordinates have y pointing down; curves are sent and stored with y up.
  const padToCurve = (points) => points.map(([x, y]) => [x, PAD_H - y]);
  const curveToPad = (points) => points.map(([x, y]) => [x, PAD_H - y]);

  function pathData(points, closed) {
    if (!points.length) return "";
    const body = points.map(([x, y], i) => `${i ? "L" : "M"}${x.toFixed(2)} ${y.toFixed(2)}`).join(" ");
    return closed ? `${body} Z` : body;
  }

  function svgEl(name, attrs) {
    const el = document.createElementNS(SVG_NS, name);
    for (const [key, value] of Object.entries(attrs)) el.setAttribute(key, value);
    return el;
  }

  // Bounds of every set of points (y up), padded, as an SVG viewBox with y flipped by a transform.
  function fitView(sets) {
    let minX = Infinity;
    let minY = Infinity;
    let maxX = -Infinity;
    let maxY = -Infinity;
    for (const points of sets) {
      for (const [x, y] of points) {
        minX = Math.min(minX, x);
        maxX = Math.max(maxX, x);
        minY = Math.min(minY, y);
        maxY = Math.max(maxY, y);
      }
    }
    if (!Number.isFinite(minX)) return { box: `0 0 ${PAD_W} ${PAD_H}`, flip: `translate(0 ${PAD_H}) scale(1 -1)`, unit: 1 };
    let w = maxX - minX || 1;
    let h = maxY - minY || 1;
    // Keep the plot's 4:3 shape with the curve centred.
    if (w / h > PAD_W / PAD_H) h = (w * PAD_H) / PAD_W;
    else w = (h * PAD_W) / PAD_H;
    const cx = (minX + maxX) / 2;
    const cy = (minY + maxY) / 2;
    const margin = 0.06;
    const vw = w * (1 + 2 * margin);
    const vh = h * (1 + 2 * margin);
    return {
      box: `${cx - vw / 2} ${-(cy + vh / 2)} ${vw} ${vh}`,
      flip: "scale(1 -1)",
      unit: vw / PAD_W, // stroke widths are given for a 400-unit-wide plot
    };
  }

  function asPoints(data) {
    const points = Array.isArray(data) ? data : data && (data.points || data.data || data.curve || data.result);
    if (!Array.isArray(points)) throw new Error("The server's answer has no points.");
    // (n,) samples become (i, x) so that they can still be drawn.
    return points.map((p, i) => (Array.isArray(p) ? [Number(p[0]), Number(p[1] ?? 0)] : [i, Number(p)]));
  }

  function maxDistance(a, b) {
    if (!a || !b || a.length !== b.length) return null;
    let worst = 0;
    for (let i = 0; i < a.length; i++) worst = Math.max(worst, Math.hypot(a[i][0] - b[i][0], a[i][1] - b[i][1]));
    return worst;
  }

  function drawCurvePlot(original, coarse, recon, closed) {
    const svg = $("curve-plot");
    const view = fitView([original, coarse || [], recon || []]);
    svg.setAttribute("viewBox", view.box);
    for (const el of [...svg.querySelectorAll("g")]) el.remove();
    const g = svgEl("g", { transform: view.flip });
    const u = view.unit;
    if (original.length) {
      g.appendChild(svgEl("path", { class: "original", d: pathData(original, closed), "stroke-width": 6 * u }));
    }
    if (coarse && coarse.length) {
      g.appendChild(svgEl("path", { class: "coarse", d: pathData(coarse, closed), "stroke-width": 1.6 * u, "stroke-dasharray": `${5 * u} ${4 * u}` }));
      for (const [x, y] of coarse) g.appendChild(svgEl("circle", { class: "coarse-pt", cx: x, cy: y, r: 2.8 * u }));
    }
    if (recon && recon.length) {
      g.appendChild(svgEl("path", { class: "recon", d: pathData(recon, closed), "stroke-width": 2 * u }));
    }
    svg.appendChild(g);
    svg.dataset.coarsePoints = coarse ? String(coarse.length) : "0";
    svg.dataset.reconPoints = recon ? String(recon.length) : "0";
  }

  // A drawing pad: pointer events (mouse, pen, touch) add points in pad coordinates.
  function makePad(svg, emptyLabel, onDone, getClosed) {
    const stroke = svg.querySelector(".pad-stroke");
    let points = [];
    let drawing = false;

    const toPad = (event) => {
      const m = svg.getScreenCTM().inverse();
      const p = new DOMPoint(event.clientX, event.clientY).matrixTransform(m);
      return [Math.max(0, Math.min(PAD_W, p.x)), Math.max(0, Math.min(PAD_H, p.y))];
    };
    const render = () => {
      stroke.setAttribute("d", pathData(points, getClosed() && !drawing && points.length > 2));
      emptyLabel.hidden = points.length > 0;
    };

    svg.addEventListener("pointerdown", (event) => {
      if (event.button !== 0) return;
      drawing = true;
      svg.setPointerCapture(event.pointerId);
      points = [toPad(event)];
      render();
      event.preventDefault();
    });
    svg.addEventListener("pointermove", (event) => {
      if (!drawing) return;
      const p = toPad(event);
      const last = points[points.length - 1];
      // Thin the stroke: a point per ~2 pad units is plenty, and keeps the upload small.
      if (Math.hypot(p[0] - last[0], p[1] - last[1]) >= 2) {
        points.push(p);
        render();
      }
    });
    const finish = () => {
      if (!drawing) return;
      drawing = false;
      render();
      onDone(points.slice());
    };
    svg.addEventListener("pointerup", finish);
    svg.addEventListener("pointercancel", finish);

    return {
      set(newPoints) {
        points = clonePoints(newPoints);
        render();
      },
      clear() {
        points = [];
        render();
      },
      render,
    };
  }

  // ---------------------------------------------------------------- encode

  // Deeper than 8 levels only pads a picture out to a huge size (2^levels × 3 pixels a side).
  const MAX_LEVELS = 8;

  async function encode() {
    clearErrors(...ENCODE_ERRORS);
    if (state.mode === "bundle") return;
    const settings = readSettings();
    if (settings.level !== undefined) {
      const level = Number(settings.level);
      if (!Number.isInteger(level) || level < 1 || level > MAX_LEVELS) {
        showError("level-error", `Levels must be a whole number from 1 to ${MAX_LEVELS} (or empty for automatic), not “${settings.level}”.`);
        return;
      }
    }
    if (state.mode === "image") {
      if (!state.source || !(state.source instanceof Blob)) {
        showError("image-file-error", "Choose an image first (or use the sample).");
        return;
      }
      await encodeImage(state.source, settings);
    } else {
      if (state.drawn.length < 2) {
        showError("curve-file-error", "Draw a curve first (a few strokes' worth of points), or open a curve JSON file.");
        return;
      }
      // A curve from a file is encoded in its own coordinates; the pad only shows it.
      const points = state.filePoints || padToCurve(state.drawn);
      // Figure 1 works in the pad's coordinates, where the second curve is drawn.
      state.encodedPad = padToCurve(state.drawn);
      await encodeCurve(points, $("curve-closed").checked, settings);
    }
  }

  function imageForm(file, settings, wavelet) {
    const form = new FormData();
    form.append("file", file, file.name || "image.png");
    form.append("wavelet", wavelet);
    for (const [key, value] of Object.entries(settings)) form.append(key, value);
    return form;
  }

  async function encodeImage(file, settings) {
    const seq = ++state.seq.encode;
    const progress = startProgress("Uploading…");
    const wavelet = $("wavelet").value;
    try {
      const response = await request("encode", "POST", "/v1/images/encode", imageForm(file, settings, wavelet), {
        onUpload: progress.upload,
      });
      if (seq !== state.seq.encode) return;
      state.figures = {
        bytes: Number(response.header("X-Wavecore-Bytes")) || response.blob.size,
        bpp: Number(response.header("X-Wavecore-Bpp")),
        ratio: Number(response.header("X-Wavecore-Ratio")),
        psnr: response.header("X-Wavecore-PSNR"),
      };
      state.compare = null;
      state.compareSettings = { settings, file };
      const base = (file.name || "image").replace(/\.[^.]+$/, "");
      const bundle = new Blob([response.blob], { type: BUNDLE_TYPE });
      state.figuresFor = bundle; // header figures belong to this bundle only
      // "auto" names the wavelet it chose in the response.
      const used = response.header("X-Wavecore-Wavelet") || wavelet;
      await loadBundle(bundle, `${base}-${used}.wcb`, {
        original: file,
      });
    } catch (err) {
      if (!isAbort(err)) showError(err instanceof ApiError ? encodeErrorPlace(err) : "encode-error", err);
    } finally {
      if (seq === state.seq.encode) stopProgress();
    }
  }

  function curveBody(points, closed, settings, wavelet) {
    const body = { points, closed, level: null, keep: null, tolerance: null, wavelet };
    for (const [key, value] of Object.entries(settings)) body[key] = Number(value);
    return body;
  }

  async function encodeCurve(points, closed, settings) {
    const seq = ++state.seq.encode;
    const progress = startProgress("Compressing…");
    progress.upload(1);
    const body = curveBody(points, closed, settings, $("wavelet").value);
    try {
      const response = await request("encode", "POST", "/v1/curves/encode", JSON.stringify(body), {
        headers: { "Content-Type": "application/json" },
      });
      if (seq !== state.seq.encode) return;
      state.figures = {
        bytes: Number(response.header("X-Wavecore-Bytes")) || response.blob.size,
        ratio: Number(response.header("X-Wavecore-Ratio")),
      };
      state.compare = null;
      state.compareSettings = { settings, curve: { points, closed } };
      const bundle = new Blob([response.blob], { type: BUNDLE_TYPE });
      state.figuresFor = bundle;
      await loadBundle(bundle, `curve-${body.wavelet}.wcb`, {
        curve: { points, closed },
      });
    } catch (err) {
      if (!isAbort(err)) showError(err instanceof ApiError ? encodeErrorPlace(err) : "encode-error", err);
    } finally {
      if (seq === state.seq.encode) stopProgress();
    }
  }

  // ---------------------------------------------------------------- a bundle on the page

  async function inspectBundle(blob) {
    const response = await request("inspect", "POST", "/v1/bundles/inspect", blob, {
      headers: { "Content-Type": BUNDLE_TYPE },
    });
    return JSON.parse(await response.blob.text());
  }

  function reconstructURL(params) {
    const query = new URLSearchParams();
    for (const [key, value] of Object.entries(params)) if (value != null) query.set(key, String(value));
    const text = query.toString();
    return `/v1/bundles/reconstruct${text ? `?${text}` : ""}`;
  }

  function reconstruct(purpose, blob, params) {
    return request(purpose, "POST", reconstructURL(params), blob, { headers: { "Content-Type": BUNDLE_TYPE } });
  }

  // Shows a bundle: figures, sliders, original/reconstruction/coarse. `from.original` is the image
  // that was encoded and `from.curve` the curve; a bundle opened from a file has neither.
  async function loadBundle(blob, name, from) {
    const info = await inspectBundle(blob);
    state.bundle = blob;
    state.bundleName = name;
    state.info = info;
    state.loaded += 1;
    document.body.dataset.bundles = String(state.loaded);
    $("curveset-info").hidden = true;
    delete $("curve-plot").dataset.curves;
    state.kind = info.kind === "curve" ? "curve" : "image";
    document.body.dataset.kind = state.kind;
    if (info.kind !== "image" && info.kind !== "curve") {
      throw new ApiError(0, "Not shown here", `This page shows image and curve bundles; this one holds a ${info.kind}.`);
    }

    const download = $("download");
    if (state.urls.download) URL.revokeObjectURL(state.urls.download);
    state.urls.download = URL.createObjectURL(blob);
    download.href = state.urls.download;
    download.download = name;
    download.hidden = false;

    if (!$("empty").hidden && window.matchMedia("(max-width: 900px)").matches) {
      // On a phone the result is below the controls: bring the first one into view.
      $("results").scrollIntoView({ behavior: "smooth", block: "start" });
    }
    $("empty").hidden = true;
    $("figures").hidden = false;
    $("sliders").hidden = false;
    $("inspect").hidden = false;
    renderInspect(info);

    const levels = Math.max(1, Number(info.levels) || 1, liftedLevels(info));
    const levelSlider = $("level-slider");
    levelSlider.max = String(levels);
    // Curves start at the coarsest level: the control polygon, and every detail for figure 1.
    levelSlider.value = String(info.kind === "curve" ? levels : Math.min(3, levels));
    $("level-out").textContent = levelSlider.value;
    $("keep-slider").value = "100";
    $("keep-out").textContent = "100 %";
    clearErrors("keep-error", "coarse-error", "compare-error", "transfer-error");

    const imageMode = state.kind === "image";
    $("image-views").hidden = !imageMode;
    $("curve-views").hidden = imageMode;
    $("compare").hidden = Boolean(info.lossless) || (!imageMode && !from.curve);
    $("compare-views").hidden = true;
    $("compare-views").classList.toggle("two", !imageMode);
    $("cmp-cdf97-view").hidden = !imageMode;
    $("compare-help").textContent = imageMode
      ? "The same image, the paper’s B-spline, Haar and the default CDF 9/7, the same fraction of details kept: smooth versus blocky versus fewest bytes."
      : "The same curve, both wavelets, the same fraction of details kept: smooth versus angular (Haar repeats points, so only a coarse polygon is left).";
    for (const name of ["bspline2", "haar"]) {
      $(`cmp-${name}`).closest(".frame").hidden = !imageMode;
      $(`cmp-${name}-plot`).toggleAttribute("hidden", imageMode); // an SVG element has no .hidden
    }
    $("transfer").hidden = imageMode || !from.curve;
    $("compare-run").textContent = imageMode
      ? "Compare B-spline, Haar and CDF 9/7"
      : info.wavelet === "haar"
        ? "Compare with B-spline"
        : "Compare with Haar";
    $("compare-title").textContent = imageMode ? "B-spline versus Haar versus the default" : "B-spline versus Haar";

    if (imageMode) {
      clearImage("img-recon");
      clearImage("img-coarse");
      if (from.original) {
        await setImage("img-original", from.original);
        $("img-original").alt = `The original image${from.original.name ? `, ${from.original.name}` : ""}`;
        state.originalPixels = pixelsOf(from.original);
        state.curve = null;
        $("img-original").closest("figure").querySelector("figcaption").textContent = "Original";
      } else {
        state.originalPixels = null;
        $("img-original").closest("figure").querySelector("figcaption").textContent = "Stored (all details)";
      }
    } else {
      state.curve = from.curve || null;
      state.originalPixels = null;
      transferPad.clear();
      state.base = [];
      drawTransfer(null);
    }

    renderFigures(null);
    const jobs = [updateRecon(), updateCoarse()];
    if (imageMode && !from.original) jobs.push(showStored());
    await Promise.all(jobs);
  }

  // An opened bundle has no original: show what it stores (every detail) in the first column.
  async function showStored() {
    try {
      const response = await reconstruct("stored", state.bundle, { format: "png" });
      await setImage("img-original", response.blob);
      $("img-original").alt = "The image as stored in the bundle, with every detail";
    } catch (err) {
      if (!isAbort(err)) showError("keep-error", err);
    }
  }

  // The lossless coder (context coder version 5) codes 0 or 1 levels, and decode lifts deeper
  // thumbnails from the decoded picture: offer up to 5, as a block-coded bundle has.
  function liftedLevels(info) {
    const cparams = (info.header && info.header.cparams) || {};
    const shape = Array.isArray(info.shape) ? info.shape : [];
    if (!info.lossless || cparams.version !== 5 || shape.length < 2) return 0;
    return Math.min(5, Math.floor(Math.log2(Math.max(1, Math.min(shape[0], shape[1])))));
  }

  // A lossless bundle's filters: the integer lifting's per level, or none (the picture predicted).
  const LIFTING_NAMES = { legall53: "5/3", "511c": "5/11-C", haar: "Haar", bspline2: "B-spline" };
  function losslessName(info) {
    const lifting = ((info.header && info.header.lifting) || []).map((f) => LIFTING_NAMES[f] || f);
    return lifting.length ? `lossless (${[...new Set(lifting)].join(", ")})` : "lossless (predicted)";
  }

  function renderFigures(measured) {
    const info = state.info || {};
    const f = state.figures || {};
    const bytes = Number(info.total_bytes) || f.bytes;
    const raw = rawBytes(info);
    const ratio = Number.isFinite(f.ratio) && f.ratio > 0 && state.figuresFor === state.bundle ? f.ratio : raw && bytes ? raw / bytes : null;
    $("fig-bytes").textContent = formatBytes(bytes);
    $("fig-ratio").textContent = ratio ? `${ratio.toFixed(ratio < 10 ? 2 : 1)} : 1` : "–";
    $("fig-bpp").textContent = info.bpp != null ? formatNumber(info.bpp, 3) : formatNumber(f.bpp, 3);
    $("fig-wavelet").textContent = info.lossless ? losslessName(info) : info.wavelet || "–";
    const keep = sliderToKeep($("keep-slider").value);
    if (state.kind === "image") {
      let text;
      if (measured && measured.psnr != null) text = formatPsnr(measured.psnr);
      else if (keep >= 1) text = formatPsnr(info.psnr ?? f.psnr);
      else text = "–";
      $("fig-psnr").textContent = text;
    } else {
      let err = measured && measured.maxError != null ? measured.maxError : keep >= 1 ? info.max_error : null;
      $("fig-maxerr").textContent = err == null ? "–" : formatNumber(err, err < 1 ? 4 : 2);
    }
  }

  function renderInspect(info) {
    const body = $("inspect-body");
    body.textContent = "";
    const kv = document.createElement("dl");
    kv.className = "kv";
    const rows = [
      ["kind", info.kind],
      ["shape", JSON.stringify(info.shape)],
      ["dtype", info.dtype],
      ["wavelet", info.wavelet],
      ["boundary", JSON.stringify(info.boundary)],
      ["levels", info.levels],
      ["colour", info.colour],
      ["quantizer", typeof info.quantizer === "object" ? JSON.stringify(info.quantizer) : info.quantizer],
      ["coder", typeof info.coder === "object" ? JSON.stringify(info.coder) : info.coder],
      ["format version", info.version],
    ];
    for (const [key, value] of rows) {
      if (value == null) continue;
      const dt = document.createElement("dt");
      dt.textContent = key;
      const dd = document.createElement("dd");
      dd.textContent = String(value);
      kv.append(dt, dd);
    }
    body.appendChild(kv);
    if (Array.isArray(info.chunks)) {
      const table = document.createElement("table");
      table.innerHTML = "<caption class='sr-only'>Chunks, coarse to fine</caption><thead><tr><th scope='col'>chunk</th><th scope='col'>level</th><th scope='col'>bands</th><th scope='col'>bytes</th></tr></thead>";
      const tbody = document.createElement("tbody");
      info.chunks.forEach((chunk, i) => {
        const tr = document.createElement("tr");
        const cells = [
          i,
          chunk.level,
          (chunk.bands || []).map((b, j) => `${b} ${(chunk.shapes && chunk.shapes[j] ? chunk.shapes[j].join("×") : "")}`).join(", "),
          chunk.present === false ? "missing" : formatBytes(chunk.bytes),
        ];
        for (const cell of cells) {
          const td = document.createElement("td");
          td.textContent = String(cell);
          tr.appendChild(td);
        }
        tbody.appendChild(tr);
      });
      table.appendChild(tbody);
      body.appendChild(table);
    }
  }

  // ---------------------------------------------------------------- the sliders

  async function updateRecon() {
    if (!state.bundle) return;
    const seq = ++state.seq.recon;
    const keep = sliderToKeep($("keep-slider").value);
    const params = keep < 1 ? { keep } : {};
    clearErrors("keep-error");
    if (state.kind === "image") {
      setLoading("img-recon", true);
      try {
        const response = await reconstruct("recon", state.bundle, { ...params, format: "png" });
        if (seq !== state.seq.recon) return;
        const img = await setImage("img-recon", response.blob);
        img.alt = `Reconstruction keeping ${formatKeep(keep)} of the details`;
        $("recon-tag").textContent = `keep ${formatKeep(keep)}`;
        let measured = null;
        if (state.originalPixels) {
          const [a, b] = await Promise.all([state.originalPixels, pixelsOf(response.blob)]);
          if (seq !== state.seq.recon) return;
          const value = psnr(a, b);
          if (value != null) measured = { psnr: value };
        }
        renderFigures(measured);
        if (measured) $("recon-tag").textContent = `keep ${formatKeep(keep)} · ${formatPsnr(measured.psnr)}`;
        img.dataset.keep = String(keep);
        img.dataset.bundle = String(state.loaded);
      } catch (err) {
        if (!isAbort(err)) showError("keep-error", err);
      } finally {
        if (seq === state.seq.recon) setLoading("img-recon", false);
      }
    } else {
      try {
        const response = await reconstruct("recon", state.bundle, params);
        if (seq !== state.seq.recon) return;
        state.reconPoints = asPoints(JSON.parse(await response.blob.text()));
        const original = state.curve ? state.curve.points : state.reconPoints;
        const measured = state.curve ? { maxError: maxDistance(original, state.reconPoints) } : null;
        renderFigures(measured);
        redrawCurves();
        $("curve-plot").dataset.keep = String(keep);
        $("curve-plot").dataset.bundle = String(state.loaded);
      } catch (err) {
        if (!isAbort(err)) showError("keep-error", err);
      }
    }
    if (!$("compare-views").hidden) updateCompare();
  }

  async function updateCoarse() {
    if (!state.bundle) return;
    const seq = ++state.seq.coarse;
    const level = Number($("level-slider").value);
    clearErrors("coarse-error");
    if (state.kind === "image") {
      setLoading("img-coarse", true);
      try {
        const response = await reconstruct("coarse", state.bundle, { level, format: "png" });
        if (seq !== state.seq.coarse) return;
        const img = await setImage("img-coarse", response.blob);
        // Haar's coarse image is block averages: show its blocks. The B-spline's is the control
        // grid of a smooth surface: let the browser interpolate it.
        img.classList.toggle("pixelated", state.info.wavelet === "haar");
        img.alt = `Coarse approximation after ${level} level${level === 1 ? "" : "s"}, ${img.naturalWidth}×${img.naturalHeight} pixels`;
        $("coarse-tag").textContent = `level ${level} · ${img.naturalWidth}×${img.naturalHeight}`;
        img.dataset.level = String(level);
        img.dataset.bundle = String(state.loaded);
      } catch (err) {
        if (!isAbort(err)) showError("coarse-error", err);
      } finally {
        if (seq === state.seq.coarse) setLoading("img-coarse", false);
      }
    } else {
      try {
        const response = await reconstruct("coarse", state.bundle, { level });
        if (seq !== state.seq.coarse) return;
        state.coarsePoints = asPoints(JSON.parse(await response.blob.text()));
        redrawCurves();
        $("curve-plot").dataset.level = String(level);
      } catch (err) {
        if (!isAbort(err)) showError("coarse-error", err);
      }
    }
  }

  function redrawCurves() {
    const closed = state.curve ? state.curve.closed : Boolean(state.info && state.info.boundary && state.info.boundary[0] === "closed");
    const original = state.curve ? state.curve.points : [];
    drawCurvePlot(original, state.coarsePoints, state.reconPoints, closed);
    // An opened bundle has no original to draw: its legend entry would name nothing.
    document.querySelector("#curve-views .key.original").hidden = !state.curve;
  }

  function debounce(fn, ms) {
    let timer = null;
    return (...args) => {
      clearTimeout(timer);
      timer = setTimeout(() => fn(...args), ms);
    };
  }

  // ---------------------------------------------------------------- B-spline versus Haar

  // Images compare the paper's filter with Haar and with the default (cdf97); curves the first two.
  const COMPARE_IMAGE = ["bspline2", "haar", "cdf97"];

  async function runCompare() {
    clearErrors("compare-error");
    const saved = state.compareSettings;
    if (!saved || !(saved.file || saved.curve)) {
      showError("compare-error", "Compress an image or a curve first; a bundle opened from a file has no original to re-encode.");
      return;
    }
    if (saved.settings.lossless) {
      showError("compare-error", "Lossless coding has no wavelet choice; pick keep, quality or bits/pixel to compare.");
      return;
    }
    const button = $("compare-run");
    button.disabled = true;
    const label = button.textContent;
    button.textContent = "Compressing…";
    try {
      if (saved.curve) {
        const other = state.info.wavelet === "haar" ? "bspline2" : "haar";
        const response = await request("compare-encode", "POST", "/v1/curves/encode", JSON.stringify(curveBody(saved.curve.points, saved.curve.closed, saved.settings, other)), {
          headers: { "Content-Type": "application/json" },
        });
        state.compare = { [state.info.wavelet]: state.bundle, [other]: new Blob([response.blob], { type: BUNDLE_TYPE }) };
      } else {
        // The paper's filter, Haar and the default: encode the ones not on the page already.
        const compare = { [state.info.wavelet]: state.bundle };
        for (const name of COMPARE_IMAGE) {
          if (compare[name]) continue;
          const response = await request(`compare-encode-${name}`, "POST", "/v1/images/encode", imageForm(saved.file, saved.settings, name));
          compare[name] = new Blob([response.blob], { type: BUNDLE_TYPE });
        }
        state.compare = compare;
      }
      $("compare-views").hidden = false;
      await updateCompare();
    } catch (err) {
      if (!isAbort(err)) showError("compare-error", err);
    } finally {
      button.disabled = false;
      button.textContent = label;
    }
  }

  async function updateCompare() {
    if (!state.compare) return;
    if (state.kind === "curve") return updateCompareCurves();
    const seq = ++state.seq.compare;
    const keep = sliderToKeep($("keep-slider").value);
    const params = keep < 1 ? { keep, format: "png" } : { format: "png" };
    try {
      const names = COMPARE_IMAGE;
      names.forEach((name) => setLoading(`cmp-${name}`, true));
      const responses = await Promise.all(names.map((name) => reconstruct(`compare-${name}`, state.compare[name], params)));
      if (seq !== state.seq.compare) return;
      const original = state.originalPixels ? await state.originalPixels : null;
      for (let i = 0; i < names.length; i++) {
        const name = names[i];
        const img = await setImage(`cmp-${name}`, responses[i].blob);
        const bytes = state.compare[name].size;
        let tag = `keep ${formatKeep(keep)} · ${formatBytes(bytes)}`;
        if (original) {
          const value = psnr(original, await pixelsOf(responses[i].blob));
          if (value != null) tag += ` · ${formatPsnr(value)}`;
        }
        $(`cmp-${name}-tag`).textContent = tag;
        img.dataset.keep = String(keep);
      }
    } catch (err) {
      if (!isAbort(err)) showError("compare-error", err);
    } finally {
      if (seq === state.seq.compare) COMPARE_IMAGE.forEach((name) => setLoading(`cmp-${name}`, false));
    }
  }

  // Both wavelets' reconstructions of the encoded curve at the slider's keep, over the original.
  async function updateCompareCurves() {
    const seq = ++state.seq.compare;
    const keep = sliderToKeep($("keep-slider").value);
    const params = keep < 1 ? { keep } : {};
    const names = ["bspline2", "haar"];
    try {
      const responses = await Promise.all(names.map((name) => reconstruct(`compare-${name}`, state.compare[name], params)));
      if (seq !== state.seq.compare) return;
      const original = state.curve ? state.curve.points : [];
      const closed = state.curve ? state.curve.closed : false;
      const curves = await Promise.all(responses.map(async (r) => asPoints(JSON.parse(await r.blob.text()))));
      const view = fitView([original, ...curves]);
      names.forEach((name, i) => {
        const svg = $(`cmp-${name}-plot`);
        svg.setAttribute("viewBox", view.box);
        for (const el of [...svg.querySelectorAll("g")]) el.remove();
        const g = svgEl("g", { transform: view.flip });
        if (original.length) g.appendChild(svgEl("path", { class: "original", d: pathData(original, closed), "stroke-width": 6 * view.unit }));
        g.appendChild(svgEl("path", { class: "recon", d: pathData(curves[i], closed), "stroke-width": 2 * view.unit }));
        svg.appendChild(g);
        svg.dataset.keep = String(keep);
        svg.dataset.points = String(curves[i].length);
        let tag = `keep ${formatKeep(keep)} · ${formatBytes(state.compare[name].size)}`;
        const worst = maxDistance(original, curves[i]);
        if (worst != null) tag += ` · max error ${worst.toPrecision(3)}`;
        $(`cmp-${name}-tag`).textContent = tag;
      });
    } catch (err) {
      if (!isAbort(err)) showError("compare-error", err);
    }
  }

  // ---------------------------------------------------------------- figure 1: details on a new base

  function drawTransfer(result) {
    const svg = $("transfer-pad");
    for (const el of [...svg.querySelectorAll("g")]) el.remove();
    svg.dataset.points = result ? String(result.length) : "0";
    if (!result) return;
    const closed = state.curve ? state.curve.closed : false;
    const g = svgEl("g", { transform: `translate(0 ${PAD_H}) scale(1 -1)` });
    g.appendChild(svgEl("path", { class: "recon", d: pathData(result, closed), fill: "none", stroke: "var(--recon)", "stroke-width": 2 }));
    svg.appendChild(g);
  }

  async function transfer(basePad) {
    clearErrors("transfer-error");
    if (!state.curve) return;
    if (basePad.length < 2) {
      showError("transfer-error", "Draw a longer base curve.");
      return;
    }
    const seq = ++state.seq.transfer;
    const body = {
      source: state.encodedPad || state.curve.points,
      base: padToCurve(basePad),
      closed: state.curve.closed,
      level: Number($("level-slider").value),
    };
    try {
      const response = await request("transfer", "POST", "/v1/curves/transfer", JSON.stringify(body), {
        headers: { "Content-Type": "application/json" },
      });
      if (seq !== state.seq.transfer) return;
      drawTransfer(asPoints(JSON.parse(await response.blob.text())));
    } catch (err) {
      if (!isAbort(err)) showError("transfer-error", err);
    }
  }

  // ---------------------------------------------------------------- inputs

  function chooseImage(file) {
    clearErrors(...ENCODE_ERRORS);
    if (!file) return;
    if (file.type && !file.type.startsWith("image/") && !/\.(tiff?|bmp|webp|png|jpe?g|gif)$/i.test(file.name)) {
      showError("image-file-error", `“${file.name}” does not look like an image (${file.type}). Choose a PNG, JPEG, TIFF, BMP or WebP file.`);
      return;
    }
    state.source = file;
    $("image-name").textContent = `${file.name} · ${formatBytes(file.size)}`;
    encode();
  }

  // ---------------------------------------------------------------- curve files: GeoJSON, SVG

  const CURVE_FILE_TYPES = { geojson: "application/geo+json", svg: "image/svg+xml" };
  const GEOJSON_TYPES = ["FeatureCollection", "Feature", "LineString", "MultiLineString", "Polygon", "MultiPolygon", "GeometryCollection"];

  function curveFileFormat(file, data) {
    const name = file.name.toLowerCase();
    if (name.endsWith(".svg") || file.type === "image/svg+xml") return "svg";
    if (name.endsWith(".geojson") || file.type === "application/geo+json") return "geojson";
    if (data && !Array.isArray(data) && GEOJSON_TYPES.includes(data.type)) return "geojson";
    return null;
  }

  // Draws every curve of a decoded curve set (the server's curve JSON) in the curve plot.
  function drawCurveSet(curves, summary) {
    const svg = $("curve-plot");
    const sets = curves.map((c) => asPoints(c.points));
    const view = fitView(sets);
    svg.setAttribute("viewBox", view.box);
    for (const el of [...svg.querySelectorAll("g")]) el.remove();
    const g = svgEl("g", { transform: view.flip });
    sets.forEach((points, i) => {
      g.appendChild(svgEl("path", { class: "recon set-curve", d: pathData(points, curves[i].closed), "stroke-width": 2 * view.unit }));
    });
    svg.appendChild(g);
    svg.dataset.curves = String(curves.length);
    $("empty").hidden = true;
    $("image-views").hidden = true;
    $("curve-views").hidden = false;
    $("curveset-info").hidden = false;
    $("curveset-info").textContent = summary;
  }

  async function encodeCurveFile(file, fmt) {
    const seq = ++state.seq.encode;
    const progress = startProgress("Compressing…");
    progress.upload(1);
    const settings = readSettings();
    const query = new URLSearchParams();
    if (settings.tolerance) query.set("tolerance", settings.tolerance);
    if (settings.level) query.set("level", settings.level);
    query.set("wavelet", $("wavelet").value);
    try {
      const response = await request("encode", "POST", `/v1/curves/encode?${query}`, file, {
        headers: { "Content-Type": CURVE_FILE_TYPES[fmt] },
      });
      if (seq !== state.seq.encode) return;
      const bundle = new Blob([response.blob], { type: BUNDLE_TYPE });
      const back = await reconstruct("reconstruct", bundle, { format: "json" });
      if (seq !== state.seq.encode) return;
      const data = JSON.parse(await back.blob.text());
      const bytes = Number(response.header("X-Wavecore-Bytes")) || bundle.size;
      const bound = Number(response.header("X-Wavecore-Max-Error"));
      drawCurveSet(
        data.curves,
        `${data.curves.length} curves from ${file.name}: ${formatBytes(bytes)} (the file: ${formatBytes(file.size)}), every point within ${formatNumber(bound, 4)}`,
      );
      $("curve-plot").dataset.bytes = String(bytes);
      const download = $("download");
      if (state.urls.download) URL.revokeObjectURL(state.urls.download);
      state.urls.download = URL.createObjectURL(bundle);
      download.href = state.urls.download;
      download.download = `${file.name.replace(/\.[^.]+$/, "")}.wcb`;
      download.hidden = false;
    } catch (err) {
      if (!isAbort(err)) showError("curve-file-error", err);
    } finally {
      if (seq === state.seq.encode) stopProgress();
    }
  }

  async function chooseCurveFile(file) {
    clearErrors(...ENCODE_ERRORS);
    if (!file) return;
    $("curveset-info").hidden = true;
    delete $("curve-plot").dataset.curves;
    if (curveFileFormat(file, null) === "svg") {
      encodeCurveFile(file, "svg");
      return;
    }
    let data;
    try {
      data = JSON.parse(await file.text());
    } catch (err) {
      showError("curve-file-error", `“${file.name}” is not valid JSON: ${err.message}`);
      return;
    }
    if (curveFileFormat(file, data) === "geojson") {
      encodeCurveFile(file, "geojson");
      return;
    }
    const points = Array.isArray(data) ? data : data && data.points;
    if (!Array.isArray(points) || points.length < 2 || !points.every((p) => Array.isArray(p) && p.length >= 2 && p.every(Number.isFinite))) {
      showError("curve-file-error", "Expected a list of [x, y] points, or an object with \"points\" (and optionally \"closed\").");
      return;
    }
    if (data && typeof data.closed === "boolean") $("curve-closed").checked = data.closed;
    // Fit the file's points into the pad so that they can be seen and redrawn.
    const xs = points.map((p) => p[0]);
    const ys = points.map((p) => p[1]);
    const [minX, maxX, minY, maxY] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
    const scale = Math.min((PAD_W * 0.9) / (maxX - minX || 1), (PAD_H * 0.9) / (maxY - minY || 1));
    const ox = (PAD_W - (maxX - minX) * scale) / 2;
    const oy = (PAD_H - (maxY - minY) * scale) / 2;
    state.drawn = points.map(([x, y]) => [ox + (x - minX) * scale, PAD_H - (oy + (y - minY) * scale)]);
    state.filePoints = points.map((p) => [Number(p[0]), Number(p[1])]);
    // The tolerance is in the file's units: a thousandth of its size, as the codec's default.
    $("tolerance").value = String(Number((1e-3 * Math.hypot(maxX - minX, maxY - minY)).toPrecision(2)));
    curvePad.set(state.drawn);
    encode();
  }

  async function chooseBundle(file) {
    clearErrors("bundle-file-error");
    if (!file) return;
    $("bundle-name").textContent = `${file.name} · ${formatBytes(file.size)}`;
    const progress = startProgress("Reading the bundle…");
    progress.upload(1);
    try {
      state.figures = {};
      state.compare = null;
      state.compareSettings = null;
      await loadBundle(new Blob([file], { type: BUNDLE_TYPE }), file.name, {});
    } catch (err) {
      if (!isAbort(err)) showError("bundle-file-error", err);
    } finally {
      stopProgress();
    }
  }

  // A synthetic picture with what shows wavelets best: smooth shading, hard edges, fine stripes.
  function sampleImage() {
    const size = 256;
    const canvas = document.createElement("canvas");
    canvas.width = size;
    canvas.height = size;
    const ctx = canvas.getContext("2d");
    const sky = ctx.createLinearGradient(0, 0, 0, size);
    sky.addColorStop(0, "#1d3b8f");
    sky.addColorStop(0.6, "#f3a95b");
    sky.addColorStop(1, "#f7d9a8");
    ctx.fillStyle = sky;
    ctx.fillRect(0, 0, size, size);
    const sun = ctx.createRadialGradient(180, 90, 4, 180, 90, 46);
    sun.addColorStop(0, "#fff6d5");
    sun.addColorStop(1, "rgba(255, 214, 120, 0)");
    ctx.fillStyle = sun;
    ctx.fillRect(0, 0, size, size);
    ctx.fillStyle = "#23304f";
    ctx.beginPath();
    ctx.moveTo(0, 200);
    ctx.lineTo(60, 130);
    ctx.lineTo(110, 175);
    ctx.lineTo(160, 120);
    ctx.lineTo(256, 205);
    ctx.lineTo(256, 256);
    ctx.lineTo(0, 256);
    ctx.fill();
    for (let x = 16; x < 112; x += 6) {
      ctx.fillStyle = x % 12 === 4 ? "#f4f1e8" : "#c4462d";
      ctx.fillRect(x, 212, 3, 34);
    }
    ctx.strokeStyle = "#ffffff";
    ctx.lineWidth = 3;
    ctx.beginPath();
    ctx.arc(196, 214, 24, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.fillStyle = "#ffffff";
    ctx.font = "bold 22px sans-serif";
    ctx.fillText("wave", 20, 40);
    canvas.toBlob((blob) => {
      const file = new File([blob], "sample.png", { type: "image/png" });
      chooseImage(file);
    }, "image/png");
  }

  // A closed, wavy flower: smooth overall shape with fine detail.
  function sampleCurve() {
    const points = [];
    const n = 240;
    for (let i = 0; i < n; i++) {
      const t = (2 * Math.PI * i) / n;
      const r = 95 + 28 * Math.cos(5 * t) + 7 * Math.sin(23 * t);
      points.push([PAD_W / 2 + r * Math.cos(t), PAD_H / 2 + 0.95 * r * Math.sin(t)]);
    }
    $("curve-closed").checked = true;
    state.drawn = points;
    state.filePoints = null;
    curvePad.set(points);
    clearErrors(...ENCODE_ERRORS);
    encode();
  }

  function wireDrop(zone, onFile) {
    const el = $(zone);
    el.addEventListener("dragover", (event) => {
      event.preventDefault();
      el.classList.add("dragover");
    });
    el.addEventListener("dragleave", () => el.classList.remove("dragover"));
    el.addEventListener("drop", (event) => {
      event.preventDefault();
      el.classList.remove("dragover");
      const file = event.dataTransfer.files && event.dataTransfer.files[0];
      if (file) onFile(file);
    });
  }

  // ---------------------------------------------------------------- start

  const curvePad = makePad($("curve-pad"), $("pad-empty"), (points) => {
    state.drawn = points;
    state.filePoints = null;
    clearErrors(...ENCODE_ERRORS);
    if (points.length >= 2) encode();
  }, () => $("curve-closed").checked);

  const transferPad = makePad($("transfer-pad"), $("transfer-empty"), (points) => {
    state.base = points;
    transfer(points);
  }, () => Boolean(state.curve && state.curve.closed));

  // Errors name their control so that it is marked aria-invalid.
  const errorOwners = {
    "image-file-error": "image-file",
    "curve-file-error": "curve-file",
    "bundle-file-error": "bundle-file",
    "wavelet-error": "wavelet",
    "level-error": "level",
    "keep-error": "keep-slider",
    "coarse-error": "level-slider",
  };
  for (const [errorId, controlId] of Object.entries(errorOwners)) {
    $(errorId).dataset.for = controlId;
    $(controlId).setAttribute("aria-describedby", [$(controlId).getAttribute("aria-describedby"), errorId].filter(Boolean).join(" "));
  }

  for (const radio of document.querySelectorAll('input[name="mode"]')) {
    radio.addEventListener("change", () => setMode(radio.value));
  }
  for (const radio of document.querySelectorAll('input[name="target"]')) {
    radio.addEventListener("change", () => {
      showTarget();
      if (state.bundle && state.mode !== "bundle") encode();
    });
  }
  $("image-file").addEventListener("change", (event) => chooseImage(event.target.files[0]));
  $("curve-file").addEventListener("change", (event) => chooseCurveFile(event.target.files[0]));
  $("bundle-file").addEventListener("change", (event) => chooseBundle(event.target.files[0]));
  wireDrop("image-drop", chooseImage);
  wireDrop("bundle-drop", chooseBundle);
  $("sample-image").addEventListener("click", sampleImage);
  $("sample-curve").addEventListener("click", sampleCurve);
  $("curve-clear").addEventListener("click", () => {
    state.drawn = [];
    state.filePoints = null;
    curvePad.clear();
  });
  $("curve-closed").addEventListener("change", () => {
    curvePad.render();
    if (state.drawn.length >= 2 && state.bundle) encode();
  });
  $("transfer-clear").addEventListener("click", () => {
    transferPad.clear();
    drawTransfer(null);
  });

  $("settings").addEventListener("submit", (event) => {
    event.preventDefault();
    encode();
  });
  // A changed setting re-encodes what is on the page (number fields on change, i.e. blur/Enter).
  $("wavelet").addEventListener("change", () => {
    state.waveletChosen = true;
  });
  for (const id of ["wavelet", "level", "keep", "quality", "bpp", "tolerance"]) {
    $(id).addEventListener("change", () => {
      if (state.bundle && state.mode !== "bundle" && (state.source || state.drawn.length)) encode();
    });
  }

  const reconSoon = debounce(updateRecon, 120);
  const coarseSoon = debounce(updateCoarse, 120);
  const transferSoon = debounce(transfer, 120);
  $("keep-slider").addEventListener("input", () => {
    $("keep-out").textContent = formatKeep(sliderToKeep($("keep-slider").value));
    reconSoon();
  });
  $("level-slider").addEventListener("input", () => {
    $("level-out").textContent = $("level-slider").value;
    coarseSoon();
    if (state.base.length >= 2) transferSoon(state.base);
  });
  $("compare-run").addEventListener("click", runCompare);

  setMode(document.querySelector('input[name="mode"]:checked').value);
  document.body.dataset.ready = "true";
  // Exposed for the browser tests and the curious: the slider's mapping.
  window.wavecore = { sliderToKeep, keepToSlider };
})();
