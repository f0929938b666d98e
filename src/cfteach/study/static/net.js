// Talking to the server without losing anything.
//
// Every event waits in localStorage until the server has answered it with 200 (stored),
// 202 (stored, the next page still being prepared) or 409 duplicate_event (stored by an
// earlier try whose answer was lost); nothing else removes it. A 429, a 5xx (a proxy's 502 included), an unreadable answer or a network error is
// retried with the same event id, with exponential backoff, honouring Retry-After. An event
// the server refuses for good (any other 4xx) is sent to /api/client-report and removed only
// once the server has stored that report: the researcher sees what was sent and why it was
// refused, and the page tells the participant in plain words (never the server's message).
// Events go one at a time, in order, so a later event never overtakes a retried one.

let token = null;
let troubleHook = () => {};
let troubles = 0;

export function setToken(t) { token = t; }
export function getToken() { return token; }

/** `hook(on)` is called when retrying starts (true) and when every retry has ended (false). */
export function onTrouble(hook) { troubleHook = hook; }

function trouble(delta) {
  const before = troubles;
  troubles = Math.max(0, troubles + delta);
  if (!before && troubles) troubleHook(true);
  if (before && !troubles) troubleHook(false);
}

export function uuid() {
  if (crypto.randomUUID) return crypto.randomUUID();
  const b = crypto.getRandomValues(new Uint8Array(16));
  return Array.from(b, (x) => x.toString(16).padStart(2, "0")).join("");
}

const sleep = (ms) => new Promise((ok) => setTimeout(ok, ms));

export function retryable(status) {
  return status === 0 || status === 408 || status === 429 || status >= 500;
}

// Retry-After is seconds or an HTTP date; capped so a bad header cannot park the page.
function retryAfterMs(value) {
  if (!value) return null;
  const s = Number(value);
  const ms = Number.isFinite(s) ? s * 1000 : Date.parse(value) - Date.now();
  return Number.isFinite(ms) ? Math.min(Math.max(ms, 0), 120_000) : null;
}

function backoffMs(attempt, retryAfter) {
  const base = Math.min(15_000, 250 * 2 ** Math.min(attempt, 10));
  const jittered = base * (0.75 + 0.5 * Math.random());
  return retryAfter === null ? jittered : Math.max(retryAfter, 100);
}

// One request, one answer: {status, data, retryAfter}; status 0 = no (readable) answer.
async function once(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (token) headers["X-Session-Token"] = token;
  try {
    const res = await fetch(path, { method, headers, credentials: "same-origin",
      body: body === undefined ? undefined : JSON.stringify(body) });
    let data = null;
    try { data = await res.json(); } catch { data = null; }
    const retryAfter = retryAfterMs(res.headers.get("Retry-After"));
    if (data === null || typeof data !== "object") {
      // A proxy's HTML error page, or a 200 cut short: not an answer from the study server.
      return { status: res.ok ? 0 : res.status, data: {}, retryAfter };
    }
    return { status: res.status, data, retryAfter };
  } catch {
    return { status: 0, data: {}, retryAfter: null };
  }
}

/** A request retried until it gets an answer that is not a temporary failure. */
export async function request(method, path, body) {
  for (let attempt = 0; ; attempt++) {
    const r = await once(method, path, body);
    if (!retryable(r.status)) {
      if (attempt) trouble(-1);
      return r;
    }
    if (!attempt) trouble(+1);
    await sleep(backoffMs(attempt, r.retryAfter));
  }
}

// ---- the event queue ---------------------------------------------------------------------

const pendingKey = () => `cfteach-pending-${token}`;
function loadPending() {
  try { return JSON.parse(localStorage.getItem(pendingKey()) || "[]"); } catch { return []; }
}
function savePending(list) {
  try { localStorage.setItem(pendingKey(), JSON.stringify(list)); } catch { /* full/blocked */ }
}
function updatePending(id, fn) {
  savePending(loadPending().flatMap((e) => (e.event_id === id ? fn(e) : [e])));
}
const dropPending = (id) => updatePending(id, () => []);

/** Send a report of a refused request; true once the server has stored it. */
export async function report(path, refused, event = null, reportId = null) {
  const body = { report_id: reportId || uuid(), path, http_status: refused.status,
    error: String(refused.data.error || "").slice(0, 64),
    detail: String(refused.data.detail || "").slice(0, 2000), event,
    client_ms: Math.round(performance.timeOrigin + performance.now()) };
  const size = JSON.stringify(body).length;
  if (size > 60_000) {  // an event too big for the server (413) is too big to report whole
    body.event = { ...event, payload: { too_large_to_report: size } };
  }
  const r = await request("POST", "/api/client-report", body);
  return r.status === 200;
}

async function reportRefused(ev) {
  const { refused, ...event } = ev;
  if (await report("/api/event", refused, event, event.event_id)) dropPending(ev.event_id);
  // else: it stays in localStorage and is reported again on the next visit
}

async function deliver(ev) {
  if (ev.refused) {  // refused on an earlier visit, report not yet stored
    await reportRefused(ev);
    return { ok: false, reported: true, status: ev.refused.status, ...ev.refused.data };
  }
  let r = await request("POST", "/api/event", ev);
  for (let attempt = 0; r.status === 200 && !r.data.ok; attempt++) {
    // 200 but not the study server's answer (a captive portal, say): keep it and retry.
    trouble(+1);
    await sleep(backoffMs(attempt, null));
    trouble(-1);
    r = await request("POST", "/api/event", ev);
  }
  if (r.status === 200) {
    dropPending(ev.event_id);
    return r.data;
  }
  if (r.status === 202) {  // stored; what comes next is still being prepared
    dropPending(ev.event_id);
    return { ...r.data, ok: true, preparing: true };
  }
  if (r.status === 409 && r.data.error === "duplicate_event") {
    // Stored by an earlier try whose answer was lost: ask where the session is now.
    dropPending(ev.event_id);
    const s = await request("GET", "/api/state");
    if (s.status === 200) return { ok: true, duplicate: true, state: s.data };
    return { ok: false, status: s.status, ...s.data };
  }
  const refused = { status: r.status, data: { error: r.data.error, detail: r.data.detail } };
  updatePending(ev.event_id, (e) => [{ ...e, refused }]);
  await reportRefused({ ...ev, refused });
  return { ok: false, reported: true, status: r.status, error: r.data.error };
}

let queue = Promise.resolve();
function enqueue(fn) {
  const job = queue.then(fn);
  queue = job.catch(() => {});
  return job;
}

/** Queue one event; resolves with the server's answer ({ok: true, ...}) or a refusal. */
export function post(stepIndex, type, payload = {}) {
  const ev = { event_id: uuid(), step_index: stepIndex, type, payload,
    client_ms: Math.round(performance.timeOrigin + performance.now()) };
  savePending([...loadPending(), ev]);
  return enqueue(() => deliver(ev));
}

/** Send what an earlier visit left in localStorage (before the page is drawn). */
export function flushPending() {
  return enqueue(async () => {
    for (const ev of loadPending()) await deliver(ev);
  });
}
