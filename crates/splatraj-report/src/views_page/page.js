// views.html: click to pick a part (crates/splatraj-report/src/views_page/mod.rs writes the page).
// Plain ES2017 with no library, so the page works from a file, offline, in any current browser.
"use strict";
(function () {
  const data = JSON.parse(document.getElementById("splatraj-views").textContent);
  const $ = (id) => document.getElementById(id);
  // Depth levels: z = near · (far / near)^((q − 1) / 65534), q = 0 where no surface (encode.rs).
  const STEPS = 65534;
  // Dots drawn for the Gaussians inside the ball, per view (more only slows the drawing).
  const MAX_DOTS = 20000;

  function bytes(b64) {
    const text = atob(b64);
    const out = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) out[i] = text.charCodeAt(i);
    return out;
  }

  function decodeDepth(depth) {
    const raw = bytes(depth.levels);
    const view = new DataView(raw.buffer);
    const out = new Float64Array(raw.length / 2);
    const ratio = depth.far / depth.near;
    for (let i = 0; i < out.length; i++) {
      const q = view.getUint16(2 * i, true);
      out[i] = q === 0 ? NaN : depth.near * Math.pow(ratio, (q - 1) / STEPS);
    }
    return out;
  }

  function decodeCentres(b64) {
    const raw = bytes(b64);
    const view = new DataView(raw.buffer);
    const out = new Float32Array(raw.length / 4);
    for (let i = 0; i < out.length; i++) out[i] = view.getFloat32(4 * i, true);
    return out;
  }

  const views = data.views.map((v) => Object.assign({}, v, { z: decodeDepth(v.depth) }));
  const centres = decodeCentres(data.centres);
  const exact = data.sampled >= data.gaussians;
  const smallest = Math.pow(10, -data.decimals);

  // The camera of `v`: world point from pixel (i, j) at depth z, and back.
  function unproject(v, i, j, z) {
    const x = ((i + 0.5 - v.cx) / v.fx) * z;
    const y = ((j + 0.5 - v.cy) / v.fy) * z;
    const r = v.rotation_wc;
    return [
      v.pose[3] + r[0] * x + r[1] * y + r[2] * z,
      v.pose[4] + r[3] * x + r[4] * y + r[5] * z,
      v.pose[5] + r[6] * x + r[7] * y + r[8] * z,
    ];
  }

  function toCamera(v, p) {
    const r = v.rotation_wc;
    const d = [p[0] - v.pose[3], p[1] - v.pose[4], p[2] - v.pose[5]];
    return [
      r[0] * d[0] + r[3] * d[1] + r[6] * d[2],
      r[1] * d[0] + r[4] * d[1] + r[7] * d[2],
      r[2] * d[0] + r[5] * d[1] + r[8] * d[2],
    ];
  }

  // state.point: the ball's centre; state.view/pixel: where it was picked.
  const state = { point: null, radius: data.radius, view: null, pixel: null, parts: [] };

  // A message in the panel, or in the element `where` names (the up strip's own line).
  function setStatus(text, warn, where) {
    const el = $(where || "status");
    el.textContent = text;
    el.className = warn ? "note warn" : "note";
  }

  function fmt(x) {
    return x.toFixed(data.decimals);
  }

  function tomlKey(name) {
    return /^[A-Za-z0-9_-]+$/.test(name) ? name : JSON.stringify(name);
  }

  function line(name, point, radius) {
    const values = point.map(fmt).concat([fmt(Math.max(radius, smallest))]);
    return tomlKey(name) + " = { sphere = [" + values.join(", ") + "] }";
  }

  function countInside(point, radius) {
    const r2 = radius * radius;
    let n = 0;
    for (let k = 0; k < centres.length; k += 3) {
      const dx = centres[k] - point[0];
      const dy = centres[k + 1] - point[1];
      const dz = centres[k + 2] - point[2];
      if (dx * dx + dy * dy + dz * dz <= r2) n++;
    }
    return n;
  }

  function countText(point, radius) {
    const n = countInside(point, radius);
    if (exact) return String(n);
    const estimate = Math.round((n * data.gaussians) / Math.max(data.sampled, 1));
    return "≈ " + estimate + " (estimate: " + n + " of the " + data.sampled +
      " centres in this page, scaled to the scene's " + data.gaussians + ")";
  }

  function targetsText(withQueries) {
    if (state.parts.length === 0) return "# add a part first";
    const lines = ['[targets]', 'source = "region"', "", "[targets.regions]"];
    for (const part of state.parts) lines.push(line(part.name, part.point, part.radius));
    if (withQueries) {
      for (const part of state.parts) lines.push("", "[[queries]]", "text = " + JSON.stringify(part.name));
    }
    return lines.join("\n") + "\n";
  }

  // The projected outline of a ball: centre pixel and radius (exact for a ball on the axis).
  function ballOutline(v, point, radius) {
    const c = toCamera(v, point);
    const d2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    if (c[2] <= 0 || d2 <= radius * radius) return null;
    return {
      u: (v.fx * c[0]) / c[2] + v.cx,
      v: (v.fy * c[1]) / c[2] + v.cy,
      r: (v.fx * radius) / Math.sqrt(d2 - radius * radius),
    };
  }

  function drawBall(ctx, v, point, radius, colour, label) {
    const o = ballOutline(v, point, radius);
    if (!o) return;
    ctx.strokeStyle = colour;
    ctx.lineWidth = Math.max(1.5, v.width / 300);
    ctx.beginPath();
    ctx.arc(o.u, o.v, o.r, 0, 2 * Math.PI);
    ctx.stroke();
    if (label) {
      ctx.fillStyle = colour;
      ctx.font = Math.round(v.width / 30) + "px sans-serif";
      ctx.fillText(label, o.u + o.r * 0.72, o.v - o.r * 0.72);
    }
  }

  // The Gaussians inside the current ball, as dots where the view's depth does not hide them.
  function drawInside(ctx, v) {
    const p = state.point;
    const r2 = state.radius * state.radius;
    let drawn = 0;
    // Small and half transparent, so that the part itself still shows through.
    ctx.fillStyle = "rgba(255, 40, 200, 0.45)";
    const dot = Math.max(1, v.width / 512);
    for (let k = 0; k < centres.length && drawn < MAX_DOTS; k += 3) {
      const q = [centres[k], centres[k + 1], centres[k + 2]];
      const dx = q[0] - p[0];
      const dy = q[1] - p[1];
      const dz = q[2] - p[2];
      if (dx * dx + dy * dy + dz * dz > r2) continue;
      const c = toCamera(v, q);
      if (c[2] <= 0) continue;
      const u = (v.fx * c[0]) / c[2] + v.cx;
      const w = (v.fy * c[1]) / c[2] + v.cy;
      const i = Math.floor(u);
      const j = Math.floor(w);
      if (i < 0 || j < 0 || i >= v.width || j >= v.height) continue;
      const surface = v.z[j * v.width + i];
      // Hidden: behind the surface by more than a tenth of the ball.
      if (surface === surface && c[2] > surface + 0.1 * state.radius) continue;
      ctx.fillRect(u - dot / 2, w - dot / 2, dot, dot);
      drawn++;
    }
  }

  const canvases = Array.from(document.querySelectorAll("canvas[data-view]"));

  function draw() {
    for (const canvas of canvases) {
      const v = views[Number(canvas.dataset.view)];
      const ctx = canvas.getContext("2d");
      ctx.clearRect(0, 0, canvas.width, canvas.height);
      state.parts.forEach((part) => drawBall(ctx, v, part.point, part.radius, "#1f77b4", part.name));
      if (state.point) {
        drawInside(ctx, v);
        drawBall(ctx, v, state.point, state.radius, "#ff28c8", null);
      }
    }
  }

  function update() {
    const point = state.point;
    $("radius").value = fmt(state.radius);
    if (point) {
      $("point").textContent = "[" + point.map(fmt).join(", ") + "]";
      $("point").dataset.xyz = JSON.stringify(point);
      $("count").textContent = countText(point, state.radius);
      $("line").textContent = line($("name").value.trim() || "part", point, state.radius);
    }
    $("targets").value = targetsText(true);
    draw();
  }

  function setRadius(r) {
    if (!(r > 0) || !isFinite(r)) return;
    state.radius = Math.max(r, smallest);
    update();
  }

  // Pixel (i, j) of the view under a pointer event.
  function pixelOf(canvas, event) {
    const rect = canvas.getBoundingClientRect();
    const v = views[Number(canvas.dataset.view)];
    return {
      v: v,
      x: ((event.clientX - rect.left) * v.width) / rect.width,
      y: ((event.clientY - rect.top) * v.height) / rect.height,
    };
  }

  let drag = null;
  for (const canvas of canvases) {
    canvas.addEventListener("pointerdown", (event) => {
      const at = pixelOf(canvas, event);
      const i = Math.min(at.v.width - 1, Math.max(0, Math.floor(at.x)));
      const j = Math.min(at.v.height - 1, Math.max(0, Math.floor(at.y)));
      const z = at.v.z[j * at.v.width + i];
      if (!(z > 0)) {
        setStatus("No surface under that pixel (background): click on the scene.", true);
        return;
      }
      state.point = unproject(at.v, i, j, z);
      state.view = Number(canvas.dataset.view);
      state.pixel = [i, j];
      setStatus("Picked in view " + (state.view + 1) + " at pixel (" + i + ", " + j +
        "), depth " + z.toPrecision(5) + ". Drag out or scroll to size the ball.", false);
      drag = { canvas: canvas, x: at.x, y: at.y, z: z, moved: false };
      canvas.setPointerCapture(event.pointerId);
      update();
    });
    canvas.addEventListener("pointermove", (event) => {
      if (!drag || drag.canvas !== canvas) return;
      const at = pixelOf(canvas, event);
      const pixels = Math.hypot(at.x - drag.x, at.y - drag.y);
      // A few pixels of jitter in a click do not resize the ball.
      if (!drag.moved && pixels < 4) return;
      drag.moved = true;
      setRadius((pixels * drag.z) / at.v.fx);
    });
    const end = () => {
      drag = null;
    };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    canvas.addEventListener(
      "wheel",
      (event) => {
        if (!state.point) return;
        event.preventDefault();
        setRadius(state.radius * Math.exp(-event.deltaY * 0.001));
      },
      { passive: false },
    );
  }

  $("radius").addEventListener("change", () => setRadius(Number($("radius").value)));
  $("name").addEventListener("input", update);

  function copy(text, where) {
    const done = () => setStatus("Copied.", false, where);
    // The clipboard API needs a secure context (file:// is one in current browsers); the
    // selection route is the fallback, and the text stays visible in the panel either way.
    if (navigator.clipboard && navigator.clipboard.writeText) {
      navigator.clipboard.writeText(text).then(done, () => fallbackCopy(text, done, where));
    } else {
      fallbackCopy(text, done, where);
    }
  }

  function fallbackCopy(text, done, where) {
    const area = document.createElement("textarea");
    area.value = text;
    document.body.appendChild(area);
    area.select();
    const ok = document.execCommand && document.execCommand("copy");
    document.body.removeChild(area);
    if (ok) done();
    else setStatus("Could not copy: select the text and copy it yourself.", true, where);
  }

  $("copy-line").addEventListener("click", () => {
    if (state.point) copy($("line").textContent + "\n");
  });
  $("copy-targets").addEventListener("click", () => copy(targetsText(false)));
  $("copy-config").addEventListener("click", () => copy(targetsText(true)));
  // The "Which way is up?" strip: each button copies the `[scene]` line it carries.
  for (const button of document.querySelectorAll("button.copy-up")) {
    button.addEventListener("click", () => copy(button.dataset.copy + "\n", "up-status"));
  }

  function renderParts() {
    const list = $("parts");
    list.textContent = "";
    state.parts.forEach((part, index) => {
      const item = document.createElement("li");
      item.textContent = line(part.name, part.point, part.radius) + " ";
      const remove = document.createElement("button");
      remove.type = "button";
      remove.textContent = "remove";
      remove.addEventListener("click", () => {
        state.parts.splice(index, 1);
        renderParts();
        update();
      });
      item.appendChild(remove);
      list.appendChild(item);
    });
  }

  $("add-part").addEventListener("click", () => {
    const name = $("name").value.trim();
    if (!state.point) return setStatus("Click a part in a view first.", true);
    if (!name) return setStatus("Give the part a name.", true);
    const part = { name: name, point: state.point.slice(), radius: state.radius };
    const same = state.parts.findIndex((p) => p.name.toLowerCase() === name.toLowerCase());
    if (same >= 0) state.parts[same] = part;
    else state.parts.push(part);
    $("name").value = "part" + (state.parts.length + 1);
    renderParts();
    setStatus("Added " + name + ".", false);
    update();
  });

  // Tests and curious users read the state and decoded data from here.
  window.splatrajViews = { data: data, views: views, state: state, unproject: unproject };
  update();
})();
