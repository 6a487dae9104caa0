// The event stream (GET /api/v1/events, server-sent events; and a robot's live feed,
// follow.js) read over fetch rather than
// EventSource, which cannot send the bearer token. Opened again a second after it ends or
// fails, after a 503's Retry-After (the mapper serves so many streams), and after a 401 once
// a token is taken (apiFetch waits for it).

import { apiFetch, note, sleep } from "./state.js";

// Calls `onMessage({data})` for each event's data, as EventSource would, of the stream at
// `path` (the event stream, or a robot's live feed) until `signal` aborts.
export async function streamEvents(onMessage, path = "/events", signal = undefined) {
  while (!signal?.aborted) {
    let waitMs = 1000;
    try {
      const r = await apiFetch(path, { cache: "no-store", signal });
      if (r.ok) await readEvents(r.body, onMessage);
      else if (r.status === 503) waitMs = 1000 * (Number(r.headers.get("retry-after")) || 1);
      else throw new Error(`${path}: ${r.status}`);
    } catch (e) {
      if (!signal?.aborted) note(e);
    }
    await sleep(waitMs);
  }
}

// Events are blocks of lines ended by an empty line: `data:` lines carry the text, lines
// starting with `:` only keep the connection open.
async function readEvents(body, onMessage) {
  const reader = body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += value.replaceAll("\r", "");
    let end;
    while ((end = buffer.indexOf("\n\n")) >= 0) {
      const data = buffer
        .slice(0, end)
        .split("\n")
        .filter((l) => l.startsWith("data:"))
        .map((l) => l.slice(l.startsWith("data: ") ? 6 : 5));
      buffer = buffer.slice(end + 2);
      if (data.length) onMessage({ data: data.join("\n") });
    }
  }
}
