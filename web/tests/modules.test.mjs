// index.html preloads exactly the modules app.js imports, directly or not, and every .js in
// web/ is one of them: a module added or dropped without its hint fails here, not as a
// slower first frame. No browser, no binary.

import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync, readdirSync } from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";

const web = path.join(path.dirname(fileURLToPath(import.meta.url)), "..");
const read = (f) => readFileSync(path.join(web, f), "utf8");

test("index.html preloads every module app.js imports, and nothing else", () => {
  const imported = new Set();
  const todo = ["app.js"];
  while (todo.length) {
    for (const [, f] of read(todo.pop()).matchAll(/^import\s[^;]*?["']\.\/([\w.-]+\.js)["']/gm)) {
      if (!imported.has(f)) {
        imported.add(f);
        todo.push(f);
      }
    }
  }
  const html = read("index.html");
  const preloaded = new Set([...html.matchAll(/rel="modulepreload" href="\/web\/([\w.-]+)"/g)].map((m) => m[1]));
  assert.deepEqual([...preloaded].sort(), [...imported].sort());
  const onDisk = readdirSync(web).filter((f) => f.endsWith(".js"));
  assert.deepEqual(onDisk.sort(), ["app.js", ...imported].sort());
});

test("geo.js: east-north metres to WGS84 and back within a millimetre", async () => {
  const { enuToGeodetic, geodeticToEnu } = await import("../geo.js");
  const datum = { latitude_deg: 52.39, longitude_deg: 9.71, height_m: 55 };
  for (const [e, n] of [[0, 0], [120.5, -80.25], [-900, 1500]]) {
    const [e2, n2] = geodeticToEnu(datum, enuToGeodetic(datum, e, n));
    assert.ok(Math.hypot(e2 - e, n2 - n) < 1e-3, `${e}, ${n} came back as ${e2}, ${n2}`);
  }
});
