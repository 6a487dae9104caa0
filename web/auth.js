// The bearer token: checked with GET /api/v1/auth (which always answers 200) before the page
// sends it, asked for by a prompt over the map when the mapper needs one to read (at the
// start, or on a 401 later), and the header's token field and re-optimize button.

import { API, state, $, note, authHeaders, sentToken, useToken, onTokenWanted, tokenWanted, apiFetch } from "./state.js";
import { refreshGraph, refreshSummary } from "./data.js";
import { refreshGrid } from "./grid.js";

// The token's standing from the mapper's answer: needed (no token, and reading needs one),
// refused, none (no token; reads open, writes need one), off (no write routes), read (the
// token reads only), ok (it writes too).
function standing(a, token) {
  if (a.authorized) return "ok";
  if (!a.read) return token ? "refused" : "needed";
  if (!a.write_routes) return "off";
  if (!token) return "none";
  return a.read_required ? "read" : "refused";
}

const WHY = {
  needed: "this mapper needs a token to show its map",
  none: "enter the mapper's bearer token to re-optimize",
  off: "the mapper has no write token: its write routes are off",
  read: "this token reads only: enter the write token to re-optimize",
  ok: "token accepted",
};

// Asks the mapper about `token` and shows the answer; the page sends it from now on if the
// mapper takes it (a refused token is never sent but here). Resolves to whether it was taken.
export async function checkToken(token = sentToken()) {
  const r = await fetch(`${API}/auth`, { headers: authHeaders(token) });
  if (!r.ok) throw new Error(`/auth: ${r.status}`);
  const a = await r.json();
  const auth = standing(a, token);
  const taken = auth !== "refused" && auth !== "needed";
  if (taken) {
    useToken(token);
    $("token").value = token;
  }
  state.auth = auth;
  document.body.dataset.auth = auth;
  const why = auth === "refused" ? `token refused: ${a.reason ?? "not a token of this mapper"}` : WHY[auth];
  $("token").title = why;
  $("optimize").disabled = auth !== "ok";
  $("optimize").title = why;
  $("optimize-status").textContent = { refused: "token refused", off: "read-only", read: "reads only" }[auth] ?? "";
  return taken;
}

// The prompt over the map, until the mapper takes a token entered there; then the map's data
// is loaded again with it.
function askForToken() {
  return new Promise((done) => {
    const form = $("token-prompt");
    form.hidden = false;
    $("token-prompt-why").textContent = "";
    $("token-prompt-input").focus();
    form.onsubmit = async (e) => {
      e.preventDefault();
      let taken = false;
      try {
        taken = await checkToken($("token-prompt-input").value.trim());
      } catch (err) {
        note(err);
      }
      if (!taken) {
        $("token-prompt-why").textContent = "token refused";
        return;
      }
      form.hidden = true;
      form.onsubmit = null;
      done();
      if (state.fleet) {
        refreshGraph();
        refreshSummary();
        refreshGrid();
      }
    };
  });
}
onTokenWanted(askForToken);

// At the start: the stored token if the mapper takes it, else the prompt, before any read.
export async function ensureToken() {
  if (!(await checkToken())) await tokenWanted();
}

$("token").value = sentToken();
$("token").addEventListener("change", (e) => checkToken(e.target.value.trim()).catch(note));
$("optimize").addEventListener("click", async () => {
  const status = $("optimize-status");
  if (!state.fleet) return;
  status.textContent = "solving…";
  try {
    const r = await apiFetch(`/fleets/${state.fleet}/optimize`, { method: "POST" });
    if (r.ok) {
      const rep = await r.json();
      status.textContent = rep.final_chi2 !== undefined ? `χ² ${rep.final_chi2.toFixed(1)}` : "done";
      refreshSummary();
      refreshGraph();
    } else {
      status.textContent = `${r.status}: ${(await r.text()).trim()}`;
      checkToken().catch(note);
    }
  } catch (e) {
    status.textContent = String(e);
  }
});
