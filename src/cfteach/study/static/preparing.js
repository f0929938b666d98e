// "Preparing the next item": the server's teacher decides a closed-loop item in a worker
// process, off the request path. Until the item is ready the server answers the state with
// `preparing: true` (at the top level or in the step) or an event with 202 Accepted; the
// page then says so and asks again, a little less often each time, instead of holding a
// request open.
import { h } from "./ui.js";

const DELAYS_MS = [250, 400, 600, 900, 1300, 2000];

/** True when the server's state says the next item is still being prepared. */
export function preparing(st) {
  return Boolean(st && (st.preparing || (st.step && st.step.preparing)));
}

const sleep = (ms) => new Promise((ok) => setTimeout(ok, ms));

/** Show the waiting page, then poll `GET /api/state` (through `request`, which retries
 * network faults) until the state is ready; resolves with the last answer. */
export async function waitWhilePreparing(app, request, st) {
  app.dataset.step = "preparing";
  app.dataset.stepIndex = String(st ? st.step_index : "");
  app.replaceChildren(h("h1", { text: "Preparing the next item\u2026" }),
    h("p", { id: "preparing", role: "status",
      text: "Chip is choosing what to show you next. This takes a moment." }));
  for (let i = 0; ; i++) {
    await sleep(DELAYS_MS[Math.min(i, DELAYS_MS.length - 1)]);
    const r = await request("GET", "/api/state");
    if (r.status !== 200 || !preparing(r.data)) return r;
  }
}
