// Browser test of the dashboard: a real demo (mapper and three simulated robots over Zenoh on
// loopback) serves the page; Debian's chromium, driven by playwright-core, loads it.
//
//   LEVELMAP_BIN=…/debug/levelmap node --test tests/
//
// Screenshots go to LEVELMAP_WEB_ARTIFACTS (default ../target/web-artifacts).

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { spawn } from "node:child_process";
import { mkdtempSync, mkdirSync, rmSync, existsSync } from "node:fs";
import { tmpdir } from "node:os";
import path from "node:path";
import net from "node:net";
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
let demo;
let demoLog = "";
let dir;
let browser;
let page;
let base;
const consoleErrors = [];

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
  // 120 s of simulated driving at 4x: 30 s of wall time with the robots moving, time enough
  // for the page to load and for two screenshots seconds apart.
  demo = spawn(
    findBinary(),
    ["demo", "--speed", "4", "--duration", "120", "--serve", "--http", `127.0.0.1:${http}`,
      "--zenoh", `tcp/127.0.0.1:${zenoh}`, "--dir", dir],
    { stdio: ["ignore", "pipe", "pipe"], env: { ...process.env, LEVELMAP_TOKEN: TOKEN } },
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
  await page.goto(`${base}/`);
});

after(async () => {
  await browser?.close();
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
});

test("the token is checked before any write, and re-optimize works with it", async () => {
  // No token stored: the button is off and says why.
  assert.equal(await page.evaluate(() => window.levelmapState.auth), "none");
  assert.equal(await page.isDisabled("#optimize"), true);
  await page.fill("#token", "wrong");
  await page.dispatchEvent("#token", "change");
  await waitFor("the refused state", () => page.evaluate(() => window.levelmapState.auth === "refused"), 5_000);
  assert.equal(await page.isDisabled("#optimize"), true);
  assert.match(await page.textContent("#optimize-status"), /token refused/);
  assert.equal(await page.evaluate(() => document.body.dataset.auth), "refused");
  await page.screenshot({ path: path.join(artifacts, "5-token-refused.png") });
  await page.fill("#token", TOKEN);
  await page.dispatchEvent("#token", "change");
  await waitFor("the accepted state", () => page.evaluate(() => window.levelmapState.auth === "ok"), 5_000);
  await page.click("#optimize");
  await waitFor("the solve's χ²", async () => /χ² \d/.test(await page.textContent("#optimize-status")), 20_000);
});

test("a tablet: panels under the map, tap to inspect, pinch to zoom", async () => {
  const tablet = await browser.newContext({ viewport: { width: 820, height: 1180 }, hasTouch: true, deviceScaleFactor: 2 });
  const tab = await tablet.newPage();
  tab.on("console", (m) => m.type() === "error" && consoleErrors.push(`tablet: ${m.text()}`));
  tab.on("pageerror", (e) => consoleErrors.push(`tablet: ${e}`));
  try {
    await tab.goto(`${base}/`);
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

test("no console errors", () => {
  assert.deepEqual(consoleErrors, []);
});
