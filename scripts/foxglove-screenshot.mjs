// A screenshot of a Foxglove-protocol viewer page, headless (docs/foxglove.md, "A layout").
//   node --experimental-websocket scripts/foxglove-screenshot.mjs URL OUT.png [wait_s=20] [width=1600] [height=1000]
// Starts Debian's chromium headless with a DevTools port, opens URL, waits, writes a PNG.
// Chromium's own --screenshot cannot do it: with --virtual-time-budget, virtual time never
// runs out while a WebSocket is open; with --timeout, it captures the page before it loads.
// Env: KEEP_SIDEBARS=1 keeps the viewer's side panels open; PAGE_LOG=1 prints the page's
// console; CHROME_LOG=1 chromium's.
import { spawn } from "node:child_process";
import { writeFileSync, mkdtempSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

const [url, out, waitS = "20", w = "1600", h = "1000"] = process.argv.slice(2);
const port = 9300 + Math.floor(Math.random() * 500);
const profile = mkdtempSync(join(tmpdir(), "lb-chrome-"));
const chrome = spawn("chromium", [
  "--headless=new", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader",
  "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", `--window-size=${w},${h}`,
  `--remote-debugging-port=${port}`, "--remote-debugging-address=127.0.0.1",
  `--user-data-dir=${profile}`, "--no-first-run", "--hide-scrollbars", "about:blank",
], { stdio: ["ignore", "ignore", process.env.CHROME_LOG ? "inherit" : "ignore"] });
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const done = (code) => { chrome.kill("SIGTERM"); process.exit(code); };
setTimeout(() => { console.error("overall timeout"); done(2); }, (Number(waitS) + 60) * 1000);

let target;
for (let i = 0; i < 100 && !target; i++) {
  try {
    const list = await (await fetch(`http://127.0.0.1:${port}/json/list`)).json();
    target = list.find((t) => t.type === "page");
  } catch { await sleep(200); }
}
if (!target) { console.error("no devtools target"); done(2); }
const ws = new WebSocket(target.webSocketDebuggerUrl);
await new Promise((r) => ws.addEventListener("open", r));
let id = 0; const pending = new Map();
ws.addEventListener("message", (ev) => {
  const m = JSON.parse(ev.data);
  if (m.id && pending.has(m.id)) { pending.get(m.id)(m); pending.delete(m.id); }
  if (m.method === "Runtime.exceptionThrown") console.error("page exception:", m.params.exceptionDetails?.exception?.description?.slice(0, 300));
  if (m.method === "Runtime.consoleAPICalled" && process.env.PAGE_LOG)
    console.error("console." + m.params.type + ":", m.params.args.map((a) => a.value ?? a.description).join(" ").slice(0, 300));
});
const send = (method, params = {}) => new Promise((r) => { const i = ++id; pending.set(i, r); ws.send(JSON.stringify({ id: i, method, params })); });
await send("Runtime.enable");
await send("Page.enable");
await send("Emulation.setDeviceMetricsOverride", { width: +w, height: +h, deviceScaleFactor: 1, mobile: false });
if (!process.env.KEEP_SIDEBARS) {
  // Lichtblick persists its workspace UI state (zustand) in localStorage["fox.workspace"]; close both sidebars.
  await send("Page.addScriptToEvaluateOnNewDocument", { source: `try { localStorage.setItem("fox.workspace", JSON.stringify({ state: { sidebars: { left: { open: false }, right: { open: false } } }, version: 1 })); } catch (e) {}` });
}
await send("Page.navigate", { url });
await sleep(Number(waitS) * 1000);
const res = await send("Page.captureScreenshot", { format: "png" });
if (!res.result?.data) { console.error("screenshot failed", JSON.stringify(res).slice(0, 300)); done(1); }
writeFileSync(out, Buffer.from(res.result.data, "base64"));
console.log("wrote", out);
done(0);
