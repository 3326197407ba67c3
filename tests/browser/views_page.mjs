// The views page (`splatraj scene views`) in a real headless browser: it loads from a file
// with no network, a click at a known pixel gives the point the view's depth and camera give
// (computed here from the page's data by another route than the page's script), dragging
// sizes the ball, and the [targets] table the page writes is accepted by `splatraj run --check`,
// which selects as many Gaussians as the page counted.
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
console.log(splatraj(["scene", "views", scene, "--out", html, "--views", "4", "--size", "256", "--up", "0,0,1"]).trim());
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

  // 3. The [targets] table: copied as the button copies it (the clipboard when the browser
  // lets us read it back, else the panel's text, which is what the button copies).
  await page.locator("#copy-config").click();
  const shown = await page.locator("#targets").inputValue();
  let copied = shown;
  try {
    await context.grantPermissions(["clipboard-read", "clipboard-write"]);
    copied = await page.evaluate(() => navigator.clipboard.readText());
  } catch (e) {
    console.log(`clipboard not readable here (${String(e).split("\n")[0]}); using the panel's text`);
  }
  assert.equal(copied, shown);
  assert.match(copied, /^\[targets\]\nsource = "region"\n\n\[targets\.regions\]\nfirst = \{ sphere = \[/);
  if (process.env.SCREENSHOT) await page.screenshot({ path: process.env.SCREENSHOT, fullPage: true });
  assert.deepEqual(errors, [], "no script errors");
  assert.deepEqual(requests, [], "no network requests");

  // 4. `run --check` accepts it and selects what the page counted.
  const config = path.join(work, "picked.toml");
  fs.writeFileSync(config, [
    'name = "picked"',
    "[scene]",
    `path = ${JSON.stringify(scene)}`,
    "up = [0.0, 0.0, 1.0]",
    "[output]",
    `runs_dir = ${JSON.stringify(path.join(work, "runs"))}`,
    "",
    copied,
  ].join("\n"));
  const check = splatraj(["run", config, "--check"]);
  for (const [q, part] of parts.entries()) {
    const m = check.match(new RegExp(`query ${q}: "${part.name}" → (\\d+) Gaussians`));
    assert.ok(m, `run --check grounds ${part.name}:\n${check}`);
    // The TOML's coordinates are rounded to the page's decimals: a Gaussian on the ball's
    // surface may fall either side.
    assert.ok(Math.abs(Number(m[1]) - part.count) <= Math.max(2, 0.01 * part.count),
      `${part.name}: run selects ${m[1]}, the page counted ${part.count}`);
  }
  assert.match(check, /check passed/);
  console.log(`run --check accepted the copied [targets] (${parts.map((p) => p.name).join(", ")})`);
} finally {
  await context.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
fs.rmSync(work, { recursive: true, force: true });
console.log("browser test: views page ok");
