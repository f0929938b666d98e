// The demonstrations page of the fixed curricula: play each demonstration (at least once
// to its end, timed by the server from the stored start), step between them, continue.
import { drawGrid } from "./grid.js";
import { fill, h } from "./ui.js";

export function demosPage(ctx, st) {
  const { app, send, advance, keepFocus } = ctx;
  const s = st.step;
  const done = s.completed.slice();
  ctx.watched(done.every((n) => n >= 1));
  let k = Math.max(0, done.findIndex((n) => n < 1));
  if (done.every((n) => n >= 1)) k = s.demos.length - 1;
  let timer = null, playing = null;
  const board = h("div", { id: "board" });
  const title = h("h2", { id: "demo-title" });
  const playBtn = h("button", { id: "play", class: "primary" });
  const prev = h("button", { id: "prev" }, "Previous");
  const next = h("button", { id: "next", class: "primary" }, "Next");
  const last = h("p", { class: "note", id: "last-note" });
  // An action the board cannot show by Chip's position (a declared exit or stay) is named
  // under the board while its frame is on screen.
  const caption = h("p", { id: "demo-action", role: "status" });
  const marked = Object.fromEntries((s.info.controls || [])
    .filter((c) => c.effect === "exit" || c.effect === "stay").map((c) => [c.action, c.label]));
  const captionAt = (d, f) => {
    const a = f > 0 ? d.actions[f - 1] : null;
    caption.textContent = a && marked[a] ? `Chip: ${marked[a]}` : "";
  };
  const stop = (completed) => {
    if (timer) clearInterval(timer);
    timer = null;
    if (playing) {
      send(st.step_index, "demo_play_end", { demo_index: playing.k, completed,
        watch_ms: Math.round(performance.now() - playing.t0) });
      playing = null;
    }
  };
  const show = () => {
    const d = s.demos[k];
    title.textContent = `Demonstration ${k + 1} of ${s.demos.length}`;
    board.replaceChildren(drawGrid(d.layout, d.states[0], { trail: [d.states[0].agent],
      label: `demonstration ${k + 1}` }));
    board.dataset.demo = String(k);
    board.dataset.frame = "0";
    captionAt(d, 0);
    playBtn.textContent = done[k] > 0 ? "Replay" : "Play";
    delete playBtn.dataset.state;
    prev.disabled = k === 0;
    next.disabled = done[k] < 1;
    next.textContent = k === s.demos.length - 1 ? "Continue" : "Next";
    last.textContent = k === s.demos.length - 1
      ? "Note: This is the last chance to review any previous demonstrations (by pressing " +
        "on the 'Previous' button below) if you wish! (You will be asked about the " +
        "informativeness and difficulty of the demonstrations on the following page.)" : "";
  };
  playBtn.addEventListener("click", async () => {
    stop(false);
    const d = s.demos[k];
    // The replay starts once the server has stored its start: a start held up by the
    // network would otherwise be timed by the server as a play too short to count.
    playBtn.disabled = prev.disabled = next.disabled = true;
    playBtn.dataset.state = "starting";
    const r = await send(st.step_index, "demo_play_start", { demo_index: k });
    if (!r.ok || !playBtn.isConnected) return;  // refused: the page has been redrawn
    playBtn.dataset.state = "playing";
    prev.disabled = k === 0;
    next.disabled = done[k] < 1;
    playing = { k, t0: performance.now() };
    let f = 0;
    const trail = [d.states[0].agent];
    timer = setInterval(() => {
      f += 1;
      if (f >= d.states.length) {
        const kk = k;
        stop(true);
        done[kk] += 1;
        ctx.watched(done.every((n) => n >= 1));
        playBtn.disabled = false;
        show();
        playBtn.dataset.state = "done";
        keepFocus(playBtn);
        board.replaceChildren(drawGrid(d.layout, d.states[d.states.length - 1],
          { trail, label: `demonstration ${kk + 1}`, banner: "Demonstration complete" }));
        board.dataset.frame = String(d.states.length - 1);
        board.dataset.watched = "true";
        captionAt(d, d.states.length - 1);
        return;
      }
      trail.push(d.states[f].agent);
      board.replaceChildren(drawGrid(d.layout, d.states[f], { trail,
        label: `demonstration ${k + 1}` }));
      board.dataset.frame = String(f);
      captionAt(d, f);
    }, s.step_ms);
  });
  prev.addEventListener("click", () => {
    stop(false);
    playBtn.disabled = false;
    k -= 1;
    show();
    keepFocus(playBtn);  // "Previous" is disabled on the first demonstration
  });
  next.addEventListener("click", () => {
    if (done[k] < 1) return;
    stop(false);
    if (k < s.demos.length - 1) { k += 1; playBtn.disabled = false; show(); }
    else advance(st.step_index, "continue");
  });
  ctx.onCleanup(() => stop(false));
  fill(app,
    h("h1", { text: "Demonstration of best strategy" }),
    h("p", { text: "Feel free to watch the demonstration as many times as you want (but at " +
      "least once)!" }),
    h("p", { text: `Task: ${s.info.task}` }),
    title, board, caption, h("div", { class: "controls" }, playBtn, " ", prev, " ", next),
    last);
  show();
}
