// Dashboard speed with a big map: time to the first frame with every node drawn, and the frame
// rate while panning. Not part of CI (it needs a mapper holding thousands of nodes):
//
//   levelmap bench-fleet --robots 100 --duration 100 --http 127.0.0.1:18555 --serve &
//   node bench/pan.mjs http://127.0.0.1:18555      # once it prints "serving"
//
// Prints one JSON object.

import { chromium } from "playwright-core";

const base = process.argv[2] || process.env.LEVELMAP_URL || "http://127.0.0.1:18555";
const panMs = Number(process.env.PAN_MS || 3000);
const sleep = (ms) => new Promise((ok) => setTimeout(ok, ms));

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync"],
});
const errors = [];
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("console", (m) => m.type() === "error" && errors.push(m.text()));
  const t0 = Date.now();
  await page.goto(`${base}/`);
  await page.waitForFunction(() => window.levelmapState?.firstFullFrameMs != null, null, { timeout: 120_000 });
  const loaded = await page.evaluate(() => {
    const s = window.levelmapState;
    const nav = performance.getEntriesByType("navigation")[0];
    return {
      nodes: s.nodes.length,
      edges: s.edges.length,
      summary_nodes: s.summary?.nodes,
      robots: Object.keys(s.robots).length,
      // performance.now() counts from the navigation's start.
      first_full_frame_ms: s.firstFullFrameMs,
      timings: s.timings,
      dom_content_loaded_ms: nav ? nav.domContentLoadedEventEnd : null,
    };
  });
  loaded.wall_to_first_full_frame_ms = Date.now() - t0;
  await sleep(1000);

  async function pan(label) {
    const box = await page.locator("#map").boundingBox();
    const cx = box.x + box.width / 2;
    const cy = box.y + box.height / 2;
    await page.evaluate(() => {
      const p = (window.__pan = { frames: [], running: true, draws0: window.levelmapState.draws });
      const tick = (t) => {
        p.frames.push(t);
        if (p.running) requestAnimationFrame(tick);
      };
      requestAnimationFrame(tick);
    });
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    const end = Date.now() + panMs;
    let k = 0;
    while (Date.now() < end) {
      // A slow circle of 150 px radius, a step every few ms.
      k += 1;
      await page.mouse.move(cx + 150 * Math.cos(k / 20) - 150, cy + 150 * Math.sin(k / 20));
    }
    await page.mouse.up();
    const r = await page.evaluate(() => {
      const p = window.__pan;
      p.running = false;
      const f = p.frames;
      const gaps = f.slice(1).map((t, i) => t - f[i]).sort((a, b) => a - b);
      const span = f[f.length - 1] - f[0];
      return {
        frames: f.length,
        span_ms: Math.round(span),
        fps: +((1000 * (f.length - 1)) / span).toFixed(1),
        frame_p50_ms: +gaps[Math.floor(gaps.length * 0.5)].toFixed(1),
        frame_p95_ms: +gaps[Math.floor(gaps.length * 0.95)].toFixed(1),
        frame_max_ms: +gaps[gaps.length - 1].toFixed(1),
        draws: window.levelmapState.draws - p.draws0,
        draw_ms_mean: +window.levelmapState.drawMsMean.toFixed(2),
      };
    });
    return { label, mouse_moves: k, ...r };
  }

  const panAll = await pan("whole map (fit), trajectories");
  await page.click("#toggle-network");
  await page.click("#fit");
  await sleep(500);
  const panNetwork = await pan("whole map (fit), pose network on");
  // Zoomed in to a park (about the middle node's): most of the map is culled.
  await page.click("#fit");
  await sleep(300);
  const at = await page.evaluate(() => window.levelmapState.nodeOnPage(Math.floor(window.levelmapState.nodes.length / 2)));
  await page.mouse.move(at.x, at.y);
  for (let i = 0; i < 12; i++) await page.mouse.wheel(0, -300);
  await sleep(300);
  const panZoomed = await pan("zoomed in, pose network on");
  // What the zoomed-in view got besides: the grid's detail and the nodes' ellipses.
  await sleep(1500);
  const zoomed = await page.evaluate(() => {
    const s = window.levelmapState;
    const grid = (g) => g && { resolution_m: +g.resolution_m.toFixed(3), width: g.width, height: g.height };
    return {
      grid_overview: grid(s.grid),
      grid_detail: grid(s.gridDetail),
      grid_detail_loads: s.gridDetailLoads,
      covariances: s.covariances.size,
      ellipses: s.ellipses,
      layer_draw_ms: s.timings.layer_draw_ms,
    };
  });
  console.log(JSON.stringify({ url: base, ...loaded, pan: [panAll, panNetwork, panZoomed], zoomed, errors }, null, 2));
} finally {
  await browser.close();
}
