// The closed_loop condition's page: one item at a time (a demonstration, a test or the
// feedback on a wrong test answer), decided by the server's teacher.
import { drawGrid } from "./grid.js";
import { Game } from "./game.js";
import { continueButton, fill, h, keyLegend } from "./ui.js";

// Animate `paths` (one list of states per board) side by side; `onDone` at the end.
// Returns a function that stops it.
function animate(layout, stepMs, boards, paths, labels, banners, highlights, onDone) {
  let f = 0;
  const n = Math.max(...paths.map((p) => p.length));
  const frame = () => boards.forEach((b, i) => {
    const p = paths[i];
    const j = Math.min(f, p.length - 1);
    b.replaceChildren(drawGrid(layout, p[j], { trail: p.slice(0, j + 1).map((x) => x.agent),
      label: labels[i], banner: f >= n - 1 ? banners[i] : null, highlight: highlights[i] }));
    b.dataset.frame = String(j);
  });
  frame();
  if (n <= 1) { onDone(); return () => {}; }
  const timer = setInterval(() => {
    f += 1;
    frame();
    if (f >= n - 1) { clearInterval(timer); onDone(); }
  }, stepMs);
  return () => clearInterval(timer);
}

/** A play button whose replay starts only once the server has stored its start event (a
 * start delayed by a network fault would otherwise make the server time a full play as a
 * short one). `run(onEnd)` animates and returns a stop function. */
function playControl(ctx, st, it, button, run, onWatched) {
  let playing = null, stopAnim = () => {};
  const stop = (completed) => {
    stopAnim();
    stopAnim = () => {};
    if (playing) {
      ctx.send(st.step_index, "demo_play_end", { demo_index: it.position, completed,
        watch_ms: Math.round(performance.now() - playing) });
      playing = null;
    }
  };
  const start = async () => {
    stop(false);
    button.disabled = true;
    button.dataset.state = "starting";
    const r = await ctx.send(st.step_index, "demo_play_start", { demo_index: it.position });
    if (!r.ok || !button.isConnected) return;  // refused: the page has been redrawn
    button.dataset.state = "playing";
    playing = performance.now();
    stopAnim = run(() => {
      stop(true);
      button.disabled = false;
      button.dataset.state = "done";
      button.textContent = "Replay";
      onWatched();
      ctx.keepFocus(button);
    });
  };
  button.addEventListener("click", start);
  ctx.onCleanup(() => stop(false));
  return { start, stop };
}

function demonstration(ctx, st, it, head, board, done) {
  const s = st.step;
  const playBtn = h("button", { id: "play", class: "primary" }, it.completed ? "Replay" : "Play");
  const next = continueButton("Continue", () => { ctl.stop(false); done(); },
    { id: "next", disabled: !it.completed });
  board.replaceChildren(drawGrid(it.layout, it.states[0], { trail: [it.states[0].agent],
    label: "demonstration" }));
  const ctl = playControl(ctx, st, it, playBtn, (end) => animate(it.layout, s.step_ms,
    [board], [it.states], ["demonstration"], ["Demonstration complete"], [null], end), () => {
    ctx.watched(true);
    board.dataset.watched = "true";
    next.disabled = false;
  });
  fill(ctx.app, h("h1", { text: it.purpose === "remedial"
    ? "Another demonstration of the best strategy" : "Demonstration of best strategy" }),
  head, h("p", { text: `Task: ${s.info.task}` }),
  h("p", { text: "Watch Chip's demonstration to the end (as many times as you like), " +
    "then continue." }), board, h("div", { class: "controls" }, playBtn, " ", next));
}

function test(ctx, st, it, head, board, done) {
  const s = st.step;
  const t0 = performance.now() - (it.elapsed_ms || 0);
  const submit = continueButton("Submit", () => {
    if (!game.ended) return;
    submit.disabled = true;
    done({ actions: game.moves, time_ms: Math.round(performance.now() - t0) });
  }, { id: "next", disabled: true });
  const game = new Game(board, it.layout, it.game, { controls: s.info.controls,
    label: "test game", onEnd: () => { submit.disabled = false; },
    onMove: (g) => { submit.disabled = !g.ended; } });
  fill(ctx.app, h("h1", { text: "Your turn" }), head,
    h("p", { text: "Show how you would complete this game's task while minimizing " +
      "Chip's energy loss. You may reset at any time before the game ends." }),
    h("p", { text: `Task: ${s.info.task}` }),
    h("div", { class: "play" }, board, keyLegend(s.info.controls)), submit);
  ctx.activate(game);
}

// The wrong answer beside Chip's best one, with both energies, the cell where the routes
// part outlined on both boards, and the server's sentence on what the difference cost.
function feedback(ctx, st, it, head, done) {
  const s = st.step;
  const x = it.explain || null;
  const mine = h("div", { id: "answer-board", class: "board" });
  const best = h("div", { id: "optimal-board", class: "board" });
  const replayBtn = h("button", { id: "play" }, "Replay");
  const next = continueButton("Continue", () => { ctl.stop(false); done(); },
    { id: "next", disabled: true });
  const part = x && x.part_cell ? [x.part_cell] : null;
  const ctl = playControl(ctx, st, it, replayBtn, (end) => animate(it.layout, s.step_ms,
    [mine, best], [it.answer, it.optimal], ["your answer", "Chip's best answer"],
    [null, null], [part, part], end), () => { ctx.watched(true); next.disabled = false; });
  const energy = (id, who, text) => h("p", { class: "energy", id },
    `${who}: `, h("strong", { text: `${text} energy` }));
  const where = x && x.part_step
    ? `The routes part at step ${x.part_step}: the dashed square marks where.` : null;
  fill(ctx.app, h("h1", { text: "Compare with Chip" }), head,
    h("p", { id: "feedback-text", text: "That was not the best strategy: your answer " +
      "(left) and Chip's best answer (right) replay side by side, so you can see where " +
      "they differ." }),
    x ? h("p", { id: "feedback-why", class: "why", text: x.sentence }) : null,
    where ? h("p", { id: "feedback-part", text: where }) : null,
    h("div", { class: "play side-by-side" },
      h("figure", {}, mine, h("figcaption", { text: "Your answer" }),
        x ? energy("answer-energy", "Your answer", x.answer_energy_text) : null),
      h("figure", {}, best, h("figcaption", { text: "Chip's best answer" }),
        x ? energy("optimal-energy", "Chip's answer", x.best_energy_text) : null)),
    h("div", { class: "controls" }, replayBtn, " ", next));
  [mine, best].forEach((b, i) => b.replaceChildren(drawGrid(it.layout, [it.answer, it.optimal][i][0],
    { trail: [it.answer[0].agent], label: i ? "Chip's best answer" : "your answer",
      highlight: part })));
  if (!started.has(st.step_index * 1000 + it.position)) {  // once: a refusal redraws
    started.add(st.step_index * 1000 + it.position);
    ctl.start();
  }
}

const started = new Set();

/** The page for one closed-loop item. `ctx`: {app, send, advance, activate, onCleanup,
 * watched(bool)} from app.js. */
export function closedLoopPage(ctx, st) {
  const it = st.step.item;
  const head = h("p", { id: "cl-item", "data-kind": it.kind,
    "data-position": String(it.position), "data-purpose": it.purpose });
  const board = h("div", { id: "board" });
  const done = (extra = {}) => ctx.advance(st.step_index, "item_done",
    { item: it.position, ...extra });
  ctx.watched(it.kind !== "demonstration" || it.completed > 0);
  if (it.kind === "demonstration") demonstration(ctx, st, it, head, board, done);
  else if (it.kind === "test") test(ctx, st, it, head, board, done);
  else feedback(ctx, st, it, head, done);
}
