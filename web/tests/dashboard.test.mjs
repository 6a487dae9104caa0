// Browser test of the dashboard: a real demo (mapper and three simulated robots over Zenoh on
// loopback) serves the page; Debian's chromium, driven by playwright-core, loads it.
//
//   LEVELMAP_BIN=…/debug/levelmap node --test tests/
//
// Screenshots go to LEVELMAP_WEB_ARTIFACTS (default ../target/web-artifacts).
// The inspector test prints how long the 3D cloud took to show after the click.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { spawn } from "node:child_process";
import { mkdtempSync, mkdirSync, rmSync, existsSync } from "node:fs";
import { tmpdir } from "node:os";
import path from "node:path";
import net from "node:net";
import { createServer } from "node:http";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, "../..");
const artifacts = process.env.LEVELMAP_WEB_ARTIFACTS || path.join(repo, "target/web-artifacts");
const sleep = (ms) => new Promise((ok) => setTimeout(ok, ms));

function findBinary() {
  const candidates = [
    process.env.LEVELMAP_BIN,
    process.env.CARGO_TARGET_DIR && path.join(process.env.CARGO_TARGET_DIR, "debug/levelmap"),
    path.join(repo, "target/debug/levelmap"),
  ].filter(Boolean);
  const found = candidates.find((p) => existsSync(p));
  if (!found) throw new Error(`no levelmap binary (tried ${candidates.join(", ")}): build it or set LEVELMAP_BIN`);
  return found;
}

function freePort() {
  return new Promise((ok, fail) => {
    const s = net.createServer();
    s.unref();
    s.on("error", fail);
    s.listen(0, "127.0.0.1", () => {
      const { port } = s.address();
      s.close(() => ok(port));
    });
  });
}

const TOKEN = "web-test-token";
// The demo's mapper needs a token to read: the page asks for it, and the tests enter it in
// the page's prompt as a user would.
const READ_TOKEN = "web-test-read-token";
let demo;
let demoLog = "";
// A base map's tile server: every tile one green square, and the tiles asked for.
const BASE_GREEN = [0, 200, 0];
const baseTiles = [];
let tileServer;
let dir;
let browser;
let page;
let base;
const consoleErrors = [];
const apiRequests = []; // every API request of the first page, in order: [path, status]

async function waitFor(what, fn, timeoutMs) {
  const end = Date.now() + timeoutMs;
  let last;
  while (Date.now() < end) {
    try {
      const v = await fn();
      if (v) return v;
    } catch (e) {
      last = e;
    }
    await sleep(250);
  }
  throw new Error(`timed out waiting for ${what}${last ? `: ${last}` : ""}\n--- demo output ---\n${demoLog.slice(-3000)}`);
}

before(async () => {
  mkdirSync(artifacts, { recursive: true });
  dir = mkdtempSync(path.join(tmpdir(), "levelmap-web-"));
  const http = await freePort();
  const zenoh = await freePort();
  base = `http://127.0.0.1:${http}`;
  tileServer = createServer((req, res) => {
    baseTiles.push(req.url);
    res.writeHead(200, { "content-type": "image/svg+xml", "access-control-allow-origin": "*" });
    res.end(`<svg xmlns="http://www.w3.org/2000/svg" width="256" height="256"><rect width="256" height="256" fill="rgb(${BASE_GREEN})"/></svg>`);
  });
  const tilePort = await freePort();
  await new Promise((ok) => tileServer.listen(tilePort, "127.0.0.1", ok));
  // 120 s of simulated driving at 4x: 30 s of wall time with the robots moving, time enough
  // for the page to load and for two screenshots seconds apart.
  demo = spawn(
    findBinary(),
    ["demo", "--speed", "4", "--duration", "120", "--serve", "--http", `127.0.0.1:${http}`,
      "--zenoh", `tcp/127.0.0.1:${zenoh}`, "--dir", dir,
      "--base-map", `http://127.0.0.1:${tilePort}/tiles/{z}/{x}/{y}.svg`],
    { stdio: ["ignore", "pipe", "pipe"], env: { ...process.env, LEVELMAP_TOKEN: TOKEN, LEVELMAP_READ_TOKEN: READ_TOKEN } },
  );
  demo.stdout.on("data", (d) => (demoLog += d));
  demo.stderr.on("data", (d) => (demoLog += d));
  await waitFor("the page", async () => (await fetch(`${base}/`)).ok, 60_000);

  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
  });
  page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  page.on("console", (m) => {
    if (m.type() === "error") consoleErrors.push(m.text());
  });
  page.on("pageerror", (e) => consoleErrors.push(String(e)));
  page.on("response", (r) => {
    const url = new URL(r.url());
    if (url.pathname.startsWith("/api/")) apiRequests.push([url.pathname, r.status()]);
  });
  await page.goto(`${base}/`);
});

// Enters `token` in the page's token prompt, as a user would.
async function enterToken(p, token) {
  await p.waitForSelector("#token-prompt:not([hidden])", { timeout: 10_000 });
  await p.fill("#token-prompt-input", token);
  await p.press("#token-prompt-input", "Enter");
}

after(async () => {
  await browser?.close();
  tileServer?.close();
  if (demo && demo.exitCode === null) {
    demo.kill("SIGINT");
    const exited = new Promise((ok) => demo.once("exit", ok));
    if (!(await Promise.race([exited.then(() => true), sleep(5000)]))) demo.kill("SIGKILL");
  }
  if (dir) rmSync(dir, { recursive: true, force: true });
});

const robotPoses = () =>
  page.evaluate(() =>
    Object.fromEntries(Object.values(window.levelmapState.robots).filter((r) => r.pose).map((r) => [r.id, r.pose])),
  );

test("the page asks for the read token before it reads, and refuses a wrong one", async () => {
  await page.waitForSelector("#token-prompt:not([hidden])", { timeout: 10_000 });
  assert.equal(await page.evaluate(() => window.levelmapState.auth), "needed");
  await enterToken(page, "not-the-token");
  await waitFor("the prompt's refusal", async () => /token refused/.test(await page.textContent("#token-prompt-why")), 5_000);
  assert.equal(await page.isVisible("#token-prompt"), true);
  await page.screenshot({ path: path.join(artifacts, "0-token-prompt.png") });
  // Nothing but the token check was asked so far: no request met a 401.
  assert.deepEqual([...new Set(apiRequests.map(([p]) => p))], ["/api/v1/auth"]);
  await enterToken(page, READ_TOKEN);
  await waitFor("the prompt to close", async () => !(await page.isVisible("#token-prompt")), 5_000);
  assert.equal(await page.evaluate(() => window.levelmapState.auth), "read");
  await waitFor("the fleet", () => page.evaluate(() => window.levelmapState.fleet), 30_000);
});

test("the robots move on the map", async () => {
  await waitFor(
    "three robots and some nodes on the page",
    () => page.evaluate(() => {
      const s = window.levelmapState;
      return s.ready && Object.values(s.robots).filter((r) => r.pose).length === 3 && s.nodes.length >= 3;
    }),
    60_000,
  );
  const first = await robotPoses();
  await page.screenshot({ path: path.join(artifacts, "1-robots.png") });
  await sleep(3000);
  const second = await robotPoses();
  await page.screenshot({ path: path.join(artifacts, "2-robots-later.png") });
  const moved = Object.keys(first).map((id) => Math.hypot(second[id].x - first[id].x, second[id].y - first[id].y));
  assert.ok(moved.every((d) => d > 1), `every robot moved over 1 m in 3 s: ${moved.map((d) => d.toFixed(2))}`);
  // The summary panel and the robots' list show the live map.
  assert.match(await page.textContent("#summary-list"), /nodes\d+/);
  assert.equal(await page.locator("#robot-list li").count(), 3);
  // Each robot's mode: the demo's robots map.
  assert.deepEqual(await page.locator("#robot-list li .mode").allTextContents(), ["maps", "maps", "maps"]);
});

test("the follow view keeps a robot in the middle and draws its live scan", async () => {
  await page.click('#robot-list li[data-robot="robot0"] button.follow');
  await waitFor("the live feed", () => page.evaluate(() => window.levelmapState.follow?.samples > 3), 10_000);
  const offsets = [];
  const start = await page.evaluate(() => window.levelmapState.follow.samples);
  for (let i = 0; i < 20; i++) {
    await sleep(250);
    const d = await page.evaluate(() => {
      const [x, y, cx, cy] = window.levelmapState.follow.drawnAt;
      return Math.hypot(x - cx, y - cy);
    });
    offsets.push(d);
  }
  const f = await page.evaluate(() => window.levelmapState.follow);
  await page.screenshot({ path: path.join(artifacts, "2b-follow.png") });
  console.log(`follow view: ${f.samples - start} samples in 5 s, largest offset ${Math.max(...offsets).toFixed(1)} px, ` +
    `${f.scanPointsDrawn} scan points drawn, feed ${f.mapperDelayMs.toFixed(0)} ms from the mapper`);
  assert.ok(Math.max(...offsets) <= 20, `the followed robot drifted from the centre: ${offsets.map((d) => d.toFixed(1))}`);
  assert.ok(f.samples - start >= 20, `${f.samples - start} live samples in 5 s`);
  // Every return of the newest live scan is drawn (the park's scans have tens of them).
  assert.ok(f.scanPointsDrawn >= 10 && f.scanPointsDrawn === f.scanReturns, `${f.scanPointsDrawn} of ${f.scanReturns} returns drawn`);
  assert.match(await page.textContent("#follow-status"), /following robot0 · feed -?\d+ ms from the mapper/);
  await page.click('#robot-list li[data-robot="robot0"] button.follow');
  await waitFor("the follow view to end", () => page.evaluate(() => window.levelmapState.follow === null), 5_000);
});

test("the status bar shows the pointer's WGS84 position", async () => {
  await waitFor("the map's GPS datum", () => page.evaluate(() => window.levelmapState.summary?.datum), 30_000);
  const box = await page.locator("#map").boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.move(box.x + box.width / 2 + 5, box.y + box.height / 2 + 5);
  const c = await page.evaluate(() => window.levelmapState.cursor);
  assert.ok(c && Number.isFinite(c.x) && Number.isFinite(c.y), `cursor in map metres: ${JSON.stringify(c)}`);
  // The simulated park lies near 52.39° N, 9.71° E; a few hundred metres is 0.01° at most.
  assert.ok(Math.abs(c.latitude_deg - 52.39) < 0.01, `latitude ${c.latitude_deg}`);
  assert.ok(Math.abs(c.longitude_deg - 9.71) < 0.01, `longitude ${c.longitude_deg}`);
  assert.match(await page.textContent("#cursor"), /52\.3\d+° N, 9\.7\d+° E/);
});

test("the pose network overlay toggles", async () => {
  assert.equal(await page.evaluate(() => window.levelmapState.showNetwork), false);
  assert.equal(await page.isVisible("#legend"), false);
  await page.click("#toggle-network");
  assert.equal(await page.evaluate(() => window.levelmapState.showNetwork), true);
  assert.equal(await page.isVisible("#legend"), true);
  // Node uncertainty: the nodes on screen get their covariance ellipses.
  await waitFor("covariances of the nodes on screen", () => page.evaluate(() => window.levelmapState.covariances.size > 0), 10_000);
  const c = await page.evaluate(() => [...window.levelmapState.covariances.values()].find((m) => m));
  assert.ok(c[0][0] > 0 && c[1][1] > 0 && c[0][0] * c[1][1] > c[0][1] ** 2, `a positive definite covariance: ${JSON.stringify(c)}`);
  assert.match(await page.textContent("#ellipses"), /95% ellipses \(\d+ nodes\)/);
  await page.screenshot({ path: path.join(artifacts, "3-network.png") });
  await page.click("#toggle-network");
  assert.equal(await page.evaluate(() => window.levelmapState.showNetwork), false);
  await page.click("#toggle-network");
});

test("clicking a node opens the inspector with its scan", async () => {
  assert.equal(await page.isVisible("#inspector"), false);
  // Stop following the robots so the node stays where it is clicked.
  await page.mouse.move(640, 400);
  await page.mouse.wheel(0, -1);
  const at = await page.evaluate(() => window.levelmapState.nodeOnPage(0));
  assert.ok(at, "node 0 is on the page");
  // When the click ended, in the page's clock (the cloud's time to show is measured from it).
  await page.evaluate(() =>
    document.getElementById("map").addEventListener("pointerup", () => (window.clickedAt = performance.now()), { once: true }),
  );
  await page.mouse.click(at.x, at.y);
  await waitFor("the inspector", () => page.evaluate(() => window.levelmapState.inspector?.points > 0), 10_000);
  const inspected = await page.evaluate(() => window.levelmapState.inspector);
  assert.ok(inspected.points > 10, `the leveled scan has points: ${inspected.points}`);
  assert.ok(inspected.counts.points > 0, "segmentation counts");
  assert.equal(await page.isVisible("#inspector"), true);
  assert.match(await page.textContent("#inspector-list"), /landmark\d+/);
  await page.screenshot({ path: path.join(artifacts, "4-inspector.png") });
});

test("the occupancy grid is drawn where the mapper placed it", async () => {
  await waitFor("the grid", () => page.evaluate(() => window.levelmapState.grid?.image), 20_000);
  const g = await page.evaluate(() => {
    const g = window.levelmapState.grid;
    return { w: g.width, h: g.height, iw: g.image.width, ih: g.image.height, res: g.resolution_m, nodes: g.nodes };
  });
  assert.equal(g.iw, g.w, "the picture is the grid the header describes");
  assert.equal(g.ih, g.h);
  assert.ok(g.res >= 0.1 && g.nodes > 0, JSON.stringify(g));
  // Zoomed out until a cell is under half a device pixel, the obstacles stay on the map as
  // near-black pixels (averaged into the free space around them they would fade to grey):
  // the dark pixels with the grid shown, less those without it.
  const cellPx = () => page.evaluate(() => window.levelmapView.scale * window.levelmapState.grid.resolution_m * (window.devicePixelRatio || 1));
  const box = await page.locator("#map").boundingBox();
  for (let i = 0; i < 10 && (await cellPx()) >= 0.5; i++) {
    await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
    await page.mouse.wheel(0, 300);
    await sleep(100);
  }
  assert.ok((await cellPx()) < 0.5, `zoomed out: ${await cellPx()} device px per cell`);
  const dark = () =>
    page.evaluate(() => {
      const c = document.getElementById("map");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      for (let i = 0; i < d.length; i += 4) if (d[i] < 60 && d[i + 1] < 60 && d[i + 2] < 60 && d[i + 3] > 200) n += 1;
      return n;
    });
  await sleep(300);
  const shown = await dark();
  await page.click("#toggle-grid");
  await sleep(300);
  const hidden = await dark();
  await page.click("#toggle-grid");
  await page.screenshot({ path: path.join(artifacts, "3b-grid-zoomed-out.png") });
  assert.ok(shown - hidden > 100, `obstacle pixels zoomed out: ${shown} with the grid, ${hidden} without`);
  console.log(`near-black pixels zoomed out (${(await cellPx()).toFixed(2)} device px per cell): ${shown} with the grid, ${hidden} without`);
  await page.click("#fit");
});

test("a configured base map is drawn under the grid, at the screen's zoom, and toggles", async () => {
  await waitFor("base map tiles", () => page.evaluate(() => window.levelmapState.baseMapTiles > 0), 20_000);
  assert.ok(await page.isVisible("#toggle-base-map"), "the base map's toggle shows when one is configured");
  const green = () =>
    page.evaluate(([r, g, b]) => {
      const c = document.getElementById("map");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      // Free cells multiply the base map by white: its own green, give or take a few levels.
      for (let i = 0; i < d.length; i += 4) if (Math.abs(d[i] - r) < 30 && Math.abs(d[i + 1] - g) < 30 && Math.abs(d[i + 2] - b) < 30) n += 1;
      return n;
    }, BASE_GREEN);
  await sleep(300);
  const shown = await green();
  const zoom = await page.evaluate(() => window.levelmapState.baseMapZoom);
  await page.screenshot({ path: path.join(artifacts, "3c-base-map.png") });
  await page.click("#toggle-base-map");
  await sleep(300);
  const hidden = await green();
  await page.click("#toggle-base-map");
  const total = await page.evaluate(() => document.getElementById("map").width * document.getElementById("map").height);
  assert.ok(shown > total / 4 && hidden < total / 100, `green pixels: ${shown} with the base map, ${hidden} without, of ${total}`);
  // The tiles asked for are the park's (52.39° N, 9.71° E) at the zoom drawn.
  const asked = baseTiles.map((u) => u.match(/^\/tiles\/(\d+)\/(\d+)\/(\d+)\.svg$/)).filter(Boolean).map((m) => m.slice(1).map(Number));
  assert.equal(asked.length, baseTiles.length, baseTiles.join(" "));
  const [z, x, y] = asked.find(([tz]) => tz === zoom) ?? [];
  assert.ok(z >= 14 && z <= 19, `zoom ${zoom}, tiles ${baseTiles.slice(-4).join(" ")}`);
  const n = 2 ** z, lat = (52.39 * Math.PI) / 180;
  const [px, py] = [((9.71 + 180) / 360) * n, ((1 - Math.log(Math.tan(lat) + 1 / Math.cos(lat)) / Math.PI) / 2) * n];
  assert.ok(Math.abs(x - px) < 8 && Math.abs(y - py) < 8, `tile ${z}/${x}/${y} for the park's ${px.toFixed(1)}, ${py.toFixed(1)}`);
  console.log(`base map: zoom ${zoom}, ${baseTiles.length} tiles asked for, ${shown} green pixels with it, ${hidden} without`);
});

test("the token is checked before any write, and re-optimize works with it", async () => {
  // The read token: the button is off and says why.
  assert.equal(await page.evaluate(() => window.levelmapState.auth), "read");
  assert.equal(await page.isDisabled("#optimize"), true);
  assert.match(await page.textContent("#optimize-status"), /reads only/);
  await page.fill("#token", "wrong");
  await page.dispatchEvent("#token", "change");
  await waitFor("the refused state", () => page.evaluate(() => window.levelmapState.auth === "refused"), 5_000);
  assert.equal(await page.isDisabled("#optimize"), true);
  assert.match(await page.textContent("#optimize-status"), /token refused/);
  assert.equal(await page.evaluate(() => document.body.dataset.auth), "refused");
  await page.screenshot({ path: path.join(artifacts, "5-token-refused.png") });
  // The refused token is not used: the page still reads with the one it had (the robots'
  // list is asked for every second).
  const since = apiRequests.length;
  await waitFor("a read after the refusal", () => apiRequests.slice(since).some(([p, status]) => p.endsWith("/robots") && status === 200), 10_000);
  await page.fill("#token", TOKEN);
  await page.dispatchEvent("#token", "change");
  await waitFor("the accepted state", () => page.evaluate(() => window.levelmapState.auth === "ok"), 5_000);
  await page.click("#optimize");
  await waitFor("the solve's χ²", async () => /χ² \d/.test(await page.textContent("#optimize-status")), 20_000);
  // No request of the page was refused for its token.
  assert.deepEqual(apiRequests.filter(([, status]) => status === 401), []);
});

test("a tablet: panels under the map, tap to inspect, pinch to zoom", async () => {
  const tablet = await browser.newContext({ viewport: { width: 820, height: 1180 }, hasTouch: true, deviceScaleFactor: 2 });
  const tab = await tablet.newPage();
  tab.on("console", (m) => m.type() === "error" && consoleErrors.push(`tablet: ${m.text()}`));
  tab.on("pageerror", (e) => consoleErrors.push(`tablet: ${e}`));
  try {
    await tab.goto(`${base}/`);
    // A new browser profile: it asks for the token too.
    await enterToken(tab, READ_TOKEN);
    await waitFor("the tablet page", () => tab.evaluate(() => window.levelmapState.ready && window.levelmapState.nodes.length > 3), 30_000);
    const map = await tab.locator("#map").boundingBox();
    const aside = await tab.locator("aside").boundingBox();
    assert.ok(map.height >= 500 && map.width >= 800, `the map fills the width: ${JSON.stringify(map)}`);
    assert.ok(aside.y >= map.y + map.height - 1, "the panels are under the map");
    assert.ok(await tab.evaluate(() => document.documentElement.scrollWidth <= window.innerWidth), "no sideways scrolling");
    for (const id of ["#toggle-network", "#toggle-grid", "#fit", "#token", "#optimize"]) {
      const b = await tab.locator(id).boundingBox();
      assert.ok(b && b.x >= 0 && b.x + b.width <= 820 && b.height >= 22, `${id} is on screen and big enough: ${JSON.stringify(b)}`);
    }
    const cdp = await tablet.newCDPSession(tab);
    const cx = map.x + map.width / 2;
    const cy = map.y + map.height / 2;
    const touch = (type, d) => cdp.send("Input.dispatchTouchEvent", {
      type,
      touchPoints: type === "touchEnd" ? [] : [{ x: cx - d, y: cy, id: 1 }, { x: cx + d, y: cy, id: 2 }],
    });
    const pinch = async (from, to) => {
      await touch("touchStart", from);
      for (let k = 1; k <= 10; k++) await touch("touchMove", from + ((to - from) * k) / 10);
      await touch("touchEnd", 0);
    };
    // A small pinch stops following the robots, so the node stays where it is tapped.
    await pinch(40, 44);
    const at = await tab.evaluate(() => window.levelmapState.nodeOnPage(0));
    assert.ok(at && at.y < map.y + map.height, "node 0 is on the map");
    await tab.touchscreen.tap(at.x, at.y);
    await waitFor("the inspector on the tablet", () => tab.evaluate(() => window.levelmapState.inspector?.points > 0), 10_000);
    // Pinching out from 80 to 320 px between the fingers zooms in 4×.
    const before = await tab.evaluate(() => window.levelmapView.scale);
    await pinch(40, 160);
    const after = await tab.evaluate(() => window.levelmapView.scale);
    assert.ok(after > before * 3 && after < before * 5, `pinch zooms in about 4×: ${before} → ${after}`);
    await tab.screenshot({ path: path.join(artifacts, "6-tablet.png") });
  } finally {
    await tablet.close();
  }
});

// The class colours of web/cloud.js, as RGB.
const CLASS_RGB = { ground: [0xb5, 0x9a, 0x6a], landmark: [0xc0, 0x39, 0x2b], overhang: [0x27, 0xae, 0x60] };

test("the inspector shows the node's segmented 3D cloud, which orbits and zooms", async () => {
  await page.waitForFunction(() => window.levelmapState.inspector?.cloud?.points > 0, null, {
    timeout: 10_000,
    polling: "raf",
  });
  const cloud = await page.evaluate(() => {
    const c = window.levelmapState.inspector.cloud;
    return { ...c, camera: { ...c.camera }, openMs: c.shownAt - window.clickedAt };
  });
  assert.equal(cloud.id, 0);
  for (const k of ["ground", "landmark", "overhang"]) assert.ok(cloud[k] > 0, `${k} points: ${JSON.stringify(cloud)}`);
  assert.equal(cloud.ground + cloud.landmark + cloud.overhang, cloud.points);
  assert.ok(cloud.points <= 6000 && cloud.source_points >= cloud.points, JSON.stringify(cloud));
  assert.ok(cloud.drawn > cloud.points * 0.8, `most points on the canvas: ${cloud.drawn} of ${cloud.points}`);
  await page.locator("#cloud").scrollIntoViewIfNeeded();
  assert.equal(await page.isVisible("#cloud"), true);
  assert.match(await page.textContent("#cloud-legend"), /ground.*landmark.*overhang/);
  assert.match(await page.textContent("#cloud-list"), /ground\d+ of \d+ \(\d+ %\)landmark\d+ of \d+/);
  // Each class's colour is on the canvas.
  const pixels = () =>
    page.evaluate((rgb) => {
      const c = document.getElementById("cloud");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
      const n = Object.fromEntries(Object.keys(rgb).map((k) => [k, 0]));
      for (let i = 0; i < d.length; i += 4) {
        if (d[i + 3] < 128) continue;
        for (const [k, [r, g, b]] of Object.entries(rgb)) {
          if (Math.abs(d[i] - r) + Math.abs(d[i + 1] - g) + Math.abs(d[i + 2] - b) < 12) n[k] += 1;
        }
      }
      return n;
    }, CLASS_RGB);
  const before = await pixels();
  for (const [k, n] of Object.entries(before)) assert.ok(n > 0, `${k} pixels on the canvas: ${JSON.stringify(before)}`);
  await page.screenshot({ path: path.join(artifacts, "7-cloud.png") });
  // Drag to orbit, wheel to zoom: the camera moves and the picture changes.
  const box = await page.locator("#cloud").boundingBox();
  const [cx, cy] = [box.x + box.width / 2, box.y + box.height / 2];
  await page.mouse.move(cx, cy);
  await page.mouse.down();
  await page.mouse.move(cx + 80, cy + 30, { steps: 8 });
  await page.mouse.up();
  await page.mouse.wheel(0, -400);
  await page.waitForFunction(() => window.levelmapState.inspector.cloud.camera.zoom > 1.5, null, { timeout: 5000 });
  const camera = await page.evaluate(() => ({ ...window.levelmapState.inspector.cloud.camera }));
  assert.ok(Math.abs(camera.yaw - cloud.camera.yaw) > 0.5, `orbited: ${JSON.stringify([cloud.camera, camera])}`);
  assert.ok(camera.pitch !== cloud.camera.pitch, "tilted");
  await sleep(100);
  assert.notDeepEqual(await pixels(), before, "redrawn from the new viewpoint");
  await page.screenshot({ path: path.join(artifacts, "8-cloud-orbited.png") });
  console.log(
    `inspector cloud: ${cloud.points} of ${cloud.source_points} points (ground ${cloud.ground}, landmark ` +
      `${cloud.landmark}, overhang ${cloud.overhang}); shown ${cloud.openMs.toFixed(0)} ms after the click, of which ` +
      `fetch + parse + first draw ${cloud.loadMs.toFixed(0)} ms (draw ${cloud.drawMs.toFixed(1)} ms)`,
  );
});

test("no console errors", () => {
  const busy = apiRequests.filter(([, status]) => status === 503).length;
  console.log(`API requests of the page: ${apiRequests.length}, answered 503 (busy): ${busy}`);
  assert.deepEqual(consoleErrors, []);
});
