// The views page (`splatraj scene views`) in a real headless browser: it loads from a file
// with no network, a click at a known pixel gives the point the view's depth and camera give
// (computed here from the page's data by another route than the page's script), dragging
// sizes the ball, and the [targets] table the page writes is accepted by `splatraj run --check`,
// which selects as many Gaussians as the page counted. The "Which way is up?" strip shows three
// distinct ups, the views' own first, and the `[scene]` line it copies is the up `run --check`
// takes.
//
//   node tests/browser/views_page.mjs      (after `npm install` here and a debug build)
//
// Environment: SPLATRAJ_BIN (default $CARGO_TARGET_DIR/debug/splatraj), CHROMIUM (default
// /usr/bin/chromium), SCREENSHOT (a PNG path: the page after picking, to look at).

import assert from "node:assert/strict";
import { spawnSync } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { pathToFileURL } from "node:url";
import { chromium } from "playwright-core";

const targetDir = process.env.CARGO_TARGET_DIR || path.join(os.homedir(), ".cache/splatraj-target");
const bin = process.env.SPLATRAJ_BIN || path.join(targetDir, "debug/splatraj");
const browserPath = process.env.CHROMIUM || "/usr/bin/chromium";
const work = fs.mkdtempSync(path.join(os.tmpdir(), "splatraj-views-"));

function splatraj(args) {
  const out = spawnSync(bin, args, { encoding: "utf8" });
  if (out.status !== 0) {
    throw new Error(`splatraj ${args.join(" ")} exited ${out.status}:\n${out.stderr}`);
  }
  return out.stderr + out.stdout;
}

// The page's data block, read from the file (not through the page's script).
function pageData(html) {
  const open = '<script type="application/json" id="splatraj-views">';
  const start = html.indexOf(open) + open.length;
  return JSON.parse(html.slice(start, html.indexOf("</script>", start)));
}

// Depth at pixel (i, j): levels are u16 little-endian, z = near·(far/near)^((q−1)/65534).
function depthAt(view, i, j) {
  const bytes = Buffer.from(view.depth.levels, "base64");
  const q = bytes.readUInt16LE(2 * (j * view.width + i));
  return q === 0 ? null : view.depth.near * Math.pow(view.depth.far / view.depth.near, (q - 1) / 65534);
}

// World point of pixel (i, j) through the 4×4 world-to-camera matrix: p = Rᵀ(p_cam − t).
function unproject(view, i, j) {
  const z = depthAt(view, i, j);
  if (z === null) return null;
  const cam = [((i + 0.5 - view.cx) / view.fx) * z, ((j + 0.5 - view.cy) / view.fy) * z, z];
  const m = view.world_to_camera;
  const d = [0, 1, 2].map((r) => cam[r] - m[r][3]);
  return [0, 1, 2].map((k) => m[0][k] * d[0] + m[1][k] * d[1] + m[2][k] * d[2]);
}

// A pixel near the middle of a view with a surface under it and around it (so the click does
// not land on an edge, where a neighbouring pixel's depth differs).
function surfacePixel(view) {
  for (let ring = 0; ring < view.width / 2; ring++) {
    for (const [di, dj] of [[ring, 0], [-ring, 0], [0, ring], [0, -ring], [ring, ring], [-ring, -ring]]) {
      const i = Math.floor(view.width / 2) + di;
      const j = Math.floor(view.height / 2) + dj;
      const z = depthAt(view, i, j);
      const around = [[1, 0], [-1, 0], [0, 1], [0, -1]].map(([a, b]) => depthAt(view, i + a, j + b));
      if (z !== null && around.every((w) => w !== null && Math.abs(w - z) < 0.01 * z)) return [i, j];
    }
  }
  throw new Error("no surface near the middle of the view");
}

// The canvas of view `index`, scrolled into sight, and its box in the viewport.
async function canvasBox(page, index) {
  const canvas = page.locator(`canvas[data-view="${index}"]`);
  await canvas.scrollIntoViewIfNeeded();
  return canvas.boundingBox();
}

async function clickPixel(page, viewIndex, view, i, j) {
  const box = await canvasBox(page, viewIndex);
  const x = box.x + ((i + 0.5) * box.width) / view.width;
  const y = box.y + ((j + 0.5) * box.height) / view.height;
  await page.mouse.click(x, y);
  return { box, x, y };
}

async function shownPoint(page) {
  return JSON.parse(await page.locator("#point").getAttribute("data-xyz"));
}

const scene = path.join(work, "demo.ply");
const html = path.join(work, "views.html");
splatraj(["scene", "demo", "--out", scene, "--gaussians", "20000"]);
// No --up: the views stand on the geometry's guess, and the strip offers it and two others.
console.log(splatraj(["scene", "views", scene, "--out", html, "--views", "4", "--size", "256"]).trim());
const data = pageData(fs.readFileSync(html, "utf8"));
assert.ok(data.views.length >= 2, "at least two views");
assert.equal(data.sampled, 20000, "all centres carried: counts exact");

const profile = fs.mkdtempSync(path.join(os.tmpdir(), "splatraj-chromium-"));
const context = await chromium.launchPersistentContext(profile, {
  executablePath: browserPath,
  headless: true,
  args: [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
  ],
  viewport: { width: 1500, height: 1000 },
});
try {
  const page = context.pages()[0] || (await context.newPage());
  // Offline: any request that is not the page itself fails the test.
  const requests = [];
  page.on("request", (r) => {
    if (!r.url().startsWith("file://") && !r.url().startsWith("data:")) requests.push(r.url());
  });
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(pathToFileURL(html).href);

  // 0. The strip: three pictures, loaded, of three distinct ups; the first is the views' own.
  const choices = await page.locator("figure.up-choice").evaluateAll((figures) =>
    figures.map((f) => ({
      up: JSON.parse(f.dataset.up),
      inUse: f.dataset.inUse === "true",
      line: f.querySelector("code.up-line").textContent,
      copies: f.querySelector("button.copy-up").dataset.copy,
      loaded: f.querySelector("img").naturalWidth > 0,
    })));
  assert.equal(choices.length, 3, "three ups to choose from");
  assert.deepEqual(choices.map((c) => c.inUse), [true, false, false]);
  assert.deepEqual(choices[0].up, data.up, "the first is the up the views use");
  for (const [k, c] of choices.entries()) {
    assert.ok(c.loaded, `picture ${k + 1} shows`);
    assert.match(c.line, /^up = \[-?[0-9.]+, -?[0-9.]+, -?[0-9.]+\]$/);
    assert.equal(c.copies, c.line);
    assert.ok(Math.abs(Math.hypot(...c.up) - 1) < 1e-6, `unit up: ${c.up}`);
    for (const d of choices.slice(k + 1)) {
      const cos = c.up.reduce((s, v, i) => s + v * d.up[i], 0);
      assert.ok(Math.abs(cos) < Math.cos((20 * Math.PI) / 180), `distinct: ${c.up} vs ${d.up}`);
    }
  }
  console.log(`up choices: ${choices.map((c) => c.line).join("; ")}`);

  // 1. A click at a known pixel gives the depth-derived point.
  const parts = [];
  for (const [index, name] of [[0, "first"], [1, "second"]]) {
    const view = data.views[index];
    const [i, j] = surfacePixel(view);
    const expected = unproject(view, i, j);
    const { box, x, y } = await clickPixel(page, index, view, i, j);
    const got = await shownPoint(page);
    const scale = Math.hypot(...view.pose.slice(3).map((c, k) => c - expected[k]));
    for (let k = 0; k < 3; k++) {
      assert.ok(Math.abs(got[k] - expected[k]) <= 1e-6 * scale,
        `view ${index} pixel (${i}, ${j}): page ${got} vs depth-derived ${expected}`);
    }
    // 2. Dragging out from the point sizes the ball: 15 CSS pixels at the point's depth.
    await page.mouse.move(x, y);
    await page.mouse.down();
    await page.mouse.move(x + 15, y, { steps: 3 });
    await page.mouse.up();
    const radius = Number(await page.locator("#radius").inputValue());
    const z = depthAt(view, i, j);
    const dragged = ((15 * view.width) / box.width) * z / view.fx;
    assert.ok(Math.abs(radius - dragged) <= 10 ** -data.decimals + 1e-9,
      `radius ${radius} vs ${dragged}`);
    const count = Number((await page.locator("#count").textContent()).trim());
    assert.ok(count > 0, `the ball holds Gaussians: ${count}`);
    await page.locator("#name").fill(name);
    await page.locator("#add-part").click();
    parts.push({ name, count });
    console.log(`view ${index}: pixel (${i}, ${j}) → [${got.map((v) => v.toFixed(4))}], radius ${radius}, ${count} Gaussians`);
  }
  // Scrolling over a view grows or shrinks the ball.
  const before = Number(await page.locator("#radius").inputValue());
  const box = await canvasBox(page, 0);
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.wheel(0, -300);
  // The wheel event is dispatched without waiting for its handler.
  await page.waitForFunction((r) => Number(document.getElementById("radius").value) !== r, before);
  const after = Number(await page.locator("#radius").inputValue());
  assert.ok(after > before, `scrolling up grows the ball: ${before} → ${after}`);

  // 3. The [targets] table and the up line: copied as the buttons copy them (the clipboard
  // when the browser lets us read it back, else the text the button carries).
  async function copyWith(button, shown) {
    await button.click();
    try {
      await context.grantPermissions(["clipboard-read", "clipboard-write"]);
      return await page.evaluate(() => navigator.clipboard.readText());
    } catch (e) {
      console.log(`clipboard not readable here (${String(e).split("\n")[0]}); using the shown text`);
      return shown;
    }
  }
  const shown = await page.locator("#targets").inputValue();
  const copied = await copyWith(page.locator("#copy-config"), shown);
  assert.equal(copied, shown);
  const upLine = await copyWith(page.locator("figure.up-choice").first().locator("button.copy-up").first(),
    choices[0].line + "\n");
  assert.equal(upLine, choices[0].line + "\n");
  assert.equal(await page.locator("#up-status").textContent(), "Copied.");
  assert.match(copied, /^\[targets\]\nsource = "region"\n\n\[targets\.regions\]\nfirst = \{ sphere = \[/);
  if (process.env.SCREENSHOT) await page.screenshot({ path: process.env.SCREENSHOT, fullPage: true });
  assert.deepEqual(errors, [], "no script errors");
  assert.deepEqual(requests, [], "no network requests");

  // 4. `run --check` accepts them: it selects what the page counted and takes the up line
  // as `scene.up` (the views' own, and another candidate's).
  const config = path.join(work, "picked.toml");
  const withUp = (line) => fs.writeFileSync(config, [
    'name = "picked"',
    "[scene]",
    `path = ${JSON.stringify(scene)}`,
    line.trim(),
    "[output]",
    `runs_dir = ${JSON.stringify(path.join(work, "runs"))}`,
    "",
    copied,
  ].join("\n"));
  const takes = (check, up) => assert.ok(
    check.includes(`up [${up.map((v) => v.toFixed(3)).join(", ")}] (config)`),
    `run --check takes up ${up}:\n${check}`);
  withUp(upLine);
  const check = splatraj(["run", config, "--check"]);
  takes(check, choices[0].up);
  for (const [q, part] of parts.entries()) {
    const m = check.match(new RegExp(`query ${q}: "${part.name}" → (\\d+) Gaussians`));
    assert.ok(m, `run --check grounds ${part.name}:\n${check}`);
    // The TOML's coordinates are rounded to the page's decimals: a Gaussian on the ball's
    // surface may fall either side.
    assert.ok(Math.abs(Number(m[1]) - part.count) <= Math.max(2, 0.01 * part.count),
      `${part.name}: run selects ${m[1]}, the page counted ${part.count}`);
  }
  assert.match(check, /check passed/);
  withUp(choices[1].line);
  takes(splatraj(["run", config, "--check"]), choices[1].up);
  console.log(`run --check accepted the copied [targets] (${parts.map((p) => p.name).join(", ")}) ` +
    `and the up lines ${choices[0].line} and ${choices[1].line}`);
} finally {
  await context.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
fs.rmSync(work, { recursive: true, force: true });
console.log("browser test: views page ok");
