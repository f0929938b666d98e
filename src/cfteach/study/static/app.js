// Participant UI: fetches the current step from the server, renders it, posts events.
// All study logic (order, assignment, scoring, gating) lives on the server; a reload simply
// asks the server again and lands on the same page.
import { demographicsPage, feedbackPage, surveyPage, testPage } from "./answers.js";
import { closedLoopPage } from "./closedloop.js";
import { demosPage } from "./demos.js";
import { Game } from "./game.js";
import { drawGrid } from "./grid.js";
import { flushPending, getToken, onTrouble, post, report, request, setToken } from "./net.js";
import { preparing, waitWhilePreparing } from "./preparing.js";
import { continueButton, count, design, fill, h, keyLegend, showError } from "./ui.js";

const app = document.getElementById("app");
// Keys and their actions come from the server, per game (`controls`: the domain's declared
// actions, or the practice game's six built-in ones), as {action, key, key_label, label}.
// A one-letter key works in either case; `r` resets a game.
const RESET_KEYS = ["r", "R"];
let gameKeys = new Set();
const TEXT_INPUTS = new Set(["text", "number", "email", "search", "tel", "url", "password"]);
setToken(sessionStorage.getItem("cfteach-token"));
let keyHandler = null;  // the game that takes the keys (a Game), or null
let cleanup = [];
let watchedAll = false;  // every demonstration on this page has played to its end here

// True where a key press types text (a comment box, the age field, a drop-down list).
function typesText(t) {
  return t instanceof HTMLTextAreaElement || t instanceof HTMLSelectElement ||
    (t instanceof HTMLInputElement && TEXT_INPUTS.has(t.type)) || Boolean(t?.isContentEditable);
}

// While a game on screen can still move, its keys go to the game, even when a radio button
// (the confidence item) or a button has the focus: otherwise the arrows would change the
// answer instead of moving Chip. Once a test game has ended it takes no key, and the arrows
// choose among the radio buttons again (keyboard-only participants answer the confidence
// item so). Text fields always keep their keys. Arrow keys and space never scroll the page.
window.addEventListener("keydown", (e) => {
  if (typesText(e.target)) return;
  const plain = !e.ctrlKey && !e.metaKey && !e.altKey;  // Ctrl+R still reloads
  if (keyHandler && keyHandler.listening && plain && gameKeys.has(e.key)) {
    e.preventDefault();
    if (!e.repeat) keyHandler.press(e);
    return;
  }
  const control = e.target instanceof HTMLInputElement || e.target instanceof HTMLButtonElement;
  if (["ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", " "].includes(e.key) && !control) {
    e.preventDefault();
  }
}, { passive: false });

// What the participant reads when the server refused a request for good. The server's own
// message (which may quote raw data) goes only into the report the researcher sees.
function plainMessage(r) {
  switch (r.error) {
    case "wrong_step":
    case "session_finished":
      return "This page was out of date (is the study open in another tab?). Here is " +
        "where you are in the study now.";
    case "demos_unwatched":
      // The page lets nobody continue before a play has ended, so a refusal after one is
      // the network's fault (a play whose events arrived late): never blame the participant.
      return watchedAll
        ? "The server could not confirm your viewing (the connection may have been " +
          "interrupted). Please play the demonstration once more; sorry for the trouble."
        : "Please watch every demonstration to the end before continuing.";
    case "no_session":
      return "We could not find your study session. Please open the study again from " +
        "its link on Prolific.";
    case "study_changed":
      return "This study has changed since you started it. Please contact the " +
        "researchers through Prolific.";
    case "bad_parameter":
      return "The study link looks incomplete. Please open it again from Prolific.";
    default:
      return "Sorry, your last step could not be saved. The researchers have been " +
        "notified. Please try again; if this keeps happening, contact them through Prolific.";
  }
}

// An event the server refused for good (net.js has already reported it): show the page the
// server is really at, with a plain message above what comes next.
async function refused(r) {
  if (await refresh()) showError(plainMessage(r));
}

/** Queue an event; a refusal is handled here (callers see `ok: false` and stop). */
async function send(stepIndex, type, payload) {
  const r = await post(stepIndex, type, payload);
  if (!r.ok) await refused(r);
  return r;
}

async function advance(stepIndex, type, payload) {
  const r = await send(stepIndex, type, payload);
  if (r.ok && r.state) render(r.state);
  else if (r.ok) await refresh();  // stored, the next page not ready yet (202 Accepted)
  return r;
}

// A button disabled while it works loses the keyboard focus to the page: give it back, so
// a keyboard user goes on from where they were.
function keepFocus(button) {
  if (!document.activeElement || document.activeElement === document.body) {
    button.focus({ preventScroll: true });
  }
}

function activate(game) {
  keyHandler = game;
  gameKeys = new Set([...Object.keys(game.keymap), ...RESET_KEYS]);
  game.host.addEventListener("click", () => game.host.focus());
  game.host.focus({ preventScroll: true });
}

// What a page module may use of this one (demos.js, answers.js, closedloop.js).
function context() {
  return { app, send, advance, activate, keepFocus, onCleanup: (f) => cleanup.push(f),
    watched: (w) => { watchedAll = w; } };
}

// ---------------------------------------------------------------------------------------
// Pages

const pages = {
  consent(st) {
    const step = st.step_index;
    const d = design(st);
    const boxes = [["adult", "I am 18 years old or older:"],
      ["read", "I have read and understand the information above:"],
      ["agree", "I want to participate in this research:"]];
    const status = h("p", { id: "eligibility" });
    const agree = continueButton("I agree", () => advance(step, "consent",
      { adult: true, read: true, agree: true }), { id: "agree", disabled: true });
    const update = () => {
      const all = boxes.every(([k]) => document.getElementById(`c-${k}`).checked);
      agree.disabled = !all;
      status.textContent = all
        ? "You are eligible to participate in our study. Do you understand and consent to these terms?"
        : "Unless you meet the above requirements, you are not eligible to complete this study.";
    };
    let custom = null;
    if (st.step.html) {  // the researcher's own consent text (from study init --consent)
      custom = h("section", { class: "consent", id: "consent-text" });
      custom.innerHTML = st.step.html;
    }
    fill(app,
      h("h1", { text: "Informed Consent Form" }),
      custom || h("section", { class: "consent" },
        h("h2", { text: "Procedures" }),
        h("p", { text: "You will watch short demonstrations of a robot playing " +
          `${d.one ? "a simple game" : `${count(d.games, "simple game")}`} and then play ` +
          `${d.one ? "it" : "the games"} yourself. This study may take up to ${d.minutes} ` +
          "minutes." }),
        h("h2", { text: "Participation Requirements" }),
        h("p", { text: "You must be 18 or older and use a desktop or laptop computer." }),
        h("h2", { text: "Risks and Benefits" }),
        h("p", { text: "The risks are no greater than those of ordinary computer use. " +
          "There is no direct benefit to you." }),
        h("h2", { text: "Compensation" }),
        h("p", { text: "You will be paid at a competitive Prolific rate." }),
        h("h2", { text: "Confidentiality" }),
        h("p", { text: "We store your Prolific ID only to pay you and keep your answers " +
          "under a random identifier. Your IP address will not be captured." }),
        h("h2", { text: "Voluntary Participation" }),
        h("p", { text: "Participation is voluntary; you may stop at any time." })),
      h("div", { class: "checks" }, boxes.map(([k, label]) => h("label", {},
        label, " ", h("input", { type: "checkbox", id: `c-${k}`, onchange: update })))),
      status, agree, " ",
      h("button", { id: "decline", onclick: () => advance(step, "decline", {}) },
      "No thanks, I do not want to do this study"));
    update();
  },

  instructions(st) {
    const d = design(st);
    fill(app,
      h("h1", { text: "Thank you for agreeing to participate in our study!" }),
      h("p", { text: "This study must be completed on a desktop or laptop on a supported " +
        `browser (Chrome, Firefox, or Safari). This task may take up to ${d.minutes} minutes.` }),
      h("p", { text: "If the page is reloaded by accident, the study continues where you " +
        "left off. Finally, directions for compensation will be presented upon completion." }),
      h("p", { text: `Chip, the blue triangle, has learned to play ${d.theGames} of this ` +
        `study perfectly! Chip will teach you the best strategy for ${d.one ? "the" : "each"} ` +
        "game through a series of " +
        "demonstrations. Following each set of demonstrations, you will show us what you " +
        "learned by playing the game yourself using your keyboard. Before we dive in, let's " +
        "head over to a practice game to get familiar with the keyboard controls and how the " +
        "games work." }),
      h("p", { class: "note", text: "Note: We recommend maximizing this window and viewing " +
        "the study in full screen for the best experience!" }),
      continueButton("Continue", () => advance(st.step_index, "continue"), { id: "next" }));
  },

  free_play(st) {
    const s = st.step;
    const board = h("div", { id: "board" });
    fill(app,
      h("h1", { text: "Free play" }),
      h("p", { text: "Each game has locations, objects you can pick up and drop, objects " +
        "you can move through, and walls. Each game will have a task that you must complete " +
        "while minimizing your energy loss." }),
      h("p", { text: "A subset of the following keys will be available to control Chip in " +
        "each game:" }),
      h("div", { class: "play" }, board, keyLegend(s.controls)),
      h("p", { text: "If you accidentally take a wrong action, you may reset the simulation " +
        "and start over. Feel free to play around with the controls. You can click the " +
        "continue button whenever you feel ready to move on." }),
      continueButton("Continue", () => advance(st.step_index, "continue"), { id: "next" }));
    activate(new Game(board, s.layout, s.game, { controls: s.controls, resetAfterEnd: true,
      label: "practice game" }));
  },

  practice(st) {
    const s = st.step;
    const board = h("div", { id: "board" });
    const info = h("p", { id: "energy" });
    const msg = h("p", { id: "practice-msg", role: "status" });
    let used = s.attempts_used;
    const left = () => s.attempts_allowed - used;
    const game = new Game(board, s.layout, s.game, {
      controls: s.controls, energy: { start: s.start_energy, weights: s.weights },
      label: "practice game",
      onMove: (g) => {
        if (!g.moves.length) msg.textContent = "";  // a new attempt: the last verdict goes
        info.textContent = `Current energy: ${Math.round(g.value)}%. Attempts remaining: ${left()}`;
        if (!g.ended && g.value <= 0) submit(g);
      },
      onEnd: (g) => submit(g),
    });
    const t0 = performance.now();
    let sending = false;
    const target = s.target_energy;
    async function submit(g) {
      if (sending) return;
      sending = true;
      const reached = Math.round(g.value);  // the server's figure replaces it below
      g.banner = { lines: [`${reached}% energy left`] };
      g.draw();
      const r = await send(st.step_index, "practice_attempt",
        { actions: g.moves, time_ms: Math.round(performance.now() - t0) });
      sending = false;
      if (!r.ok) return;  // refused: the page has been redrawn with a message
      // A retried attempt whose first answer was lost comes back as a duplicate: the
      // session's state then tells whether it passed.
      const passed = r.duplicate ? r.state.status !== "screened_out" &&
        r.state.step.kind !== "practice" : r.passed;
      const energy = Math.round(r.energy ?? g.value);
      const finished = r.finished ?? g.game.terminal[g.s];
      used = r.duplicate ? (r.state.step.attempts_used ?? used + 1) : r.attempts_used;
      if (passed) {
        g.banner = { lines: ["Game completed!", `${energy}% energy left`] };
        g.draw();
        msg.textContent = "Good job completing the task with the maximum possible energy " +
          "remaining! Click 'Continue' below.";
        keyHandler = null;
        app.appendChild(continueButton("Continue", () => render(r.state), { id: "next" }));
        return;
      }
      g.ended = true;
      g.banner = finished
        ? { lines: ["Not enough energy", `${energy}% left, ${target}% needed`], tone: "fail" }
        : { lines: ["Out of energy", `${energy}% left, ${target}% needed`], tone: "fail" };
      g.draw();
      const what = finished
        ? `You completed the task with ${energy}% energy left, but you need to finish with ` +
          `${target}% (the most possible).`
        : `Chip ran out of energy (${energy}% left) before the task was done; you need to ` +
          `finish the task with ${target}% energy left.`;
      if (r.state.status === "screened_out") {
        keyHandler = null;
        msg.textContent = `${what} I'm sorry to inform you that you don't qualify for this study.`;
        app.appendChild(continueButton("Continue", () => render(r.state), { id: "next" }));
      } else {
        msg.textContent = `${what} Press 'r' to reset and try again.`;
        game.resetAfterEnd = true;
        info.textContent = `Attempts remaining: ${left()}`;
      }
    }
    fill(app,
      h("h1", { text: "Practice game" }),
      h("table", { class: "effects" },
        h("tr", {}, h("th", { text: "Action" }), h("th", { text: "Energy change" })),
        h("tr", {}, h("td", { text: "Moving through the orange diamond" }), h("td", { text: "+10%" })),
        h("tr", {}, h("td", { text: "Any action that you take (e.g. moving right)" }),
          h("td", { text: "-5%" }))),
      h("p", { text: "Pick up the green pentagon and drop it off at the purple star with the " +
        `maximum possible energy remaining. You should end with ${s.target_energy}% energy ` +
        "left (you won't be able to move if energy falls to 0%). You will have " +
        `${s.attempts_allowed} chances to get it right to continue on with the study!` }),
      h("div", { class: "play" }, board, keyLegend(s.controls)),
      info, msg);
    game.onMove(game);
    activate(game);
  },

  post_practice(st) {
    fill(app,
      h("h1", { text: "Good job on completing the practice game!" }),
      h("p", { text: `Let's now head over to ${design(st).one ? "the main game" :
        `the ${count(design(st).games, "main game")}`} and begin the real study. ` +
        "In these games, you will not be told how each action changes Chip's energy level." }),
      h("table", { class: "effects" },
        h("tr", {}, h("th", { text: "Action" }), h("th", { text: "Energy change" })),
        h("tr", {}, h("td", { text: "Any action that you take (e.g. moving right)" }),
          h("td", { text: "???" }))),
      h("p", { text: "Instead, you will have to figure that out and subsequently the best " +
        "strategy for completing the task while minimizing energy loss by observing Chip's " +
        "demonstrations!" }),
      continueButton("Continue", () => advance(st.step_index, "continue"), { id: "next" }));
  },

  domain_intro(st) {
    const info = st.step.info;
    const examples = h("div", { class: "examples" });
    for (const ex of st.step.examples || []) {
      const box = h("div", { class: "example" });
      box.appendChild(drawGrid(ex.layout, ex.state, { label: "example configuration" }));
      examples.appendChild(box);
    }
    fill(app,
      h("h1", { text: "Welcome to a new game!" }),
      h("p", { text: "Here are a few configurations that you may see in this section." }),
      examples,
      h("p", { text: `Task: ${info.task}` }),
      h("p", { text: `The following actions affect the ${info.effects_word}:` }),
      h("table", { class: "effects" },
        h("tr", {}, h("th", { text: "Action" }), h("th", { text: "Energy change" })),
        info.actions.map((a) => h("tr", {}, h("td", { text: a }), h("td", { text: "???" })))),
      info.note ? h("p", { class: "note", text: info.note }) : null,
      h("p", { text: "Chip will now provide a few demonstrations of the best strategy for " +
        "this game." }),
      continueButton("Continue", () => advance(st.step_index, "continue"), { id: "next" }));
  },

  demos(st) {
    demosPage(context(), st);
  },

  // The closed_loop condition: one item at a time, decided by the server's teacher.
  closed_loop(st) {
    closedLoopPage(context(), st);
  },

  survey(st) {
    surveyPage(context(), st);
  },

  test(st) {
    testPage(context(), st);
  },

  feedback(st) {
    feedbackPage(context(), st);
  },

  demographics(st) {
    demographicsPage(context(), st);
  },

  complete(st) {
    finish(st, "Study complete! Your responses have been saved.");
  },

  screened_out(st) {
    finish(st, "Thank you for your time. Unfortunately you don't qualify for this study. " +
      "Please return your submission on Prolific using the code below.");
  },

  declined(st) {
    finish(st, "Thank you for your interest. As you did not consent, please return your " +
      "submission on Prolific (\"Stop without completing\" or \"Return\") so another " +
      "participant can take your place; you may also enter the code below.");
  },
};

function finish(st, text) {
  keyHandler = null;
  const s = st.step;
  fill(app, h("h1", { text: st.step.kind === "complete" ? "Thank you!" : "Study ended" }),
    h("p", { text }),
    h("p", {}, "Your completion code is ", h("strong", { id: "code", text: s.code }), "."),
    s.redirect ? h("p", {}, "You will now be taken back to Prolific. If nothing happens, ",
      h("a", { href: s.redirect, id: "redirect" }, "click here"), " or enter the code above.")
      : null);
  if (s.redirect) setTimeout(() => { window.location.href = s.redirect; }, 1500);
}

let renders = 0;  // a newer render makes an older preparing-poll drop its answer

function render(st) {
  for (const f of cleanup) f();
  cleanup = [];
  keyHandler = null;
  const mine = ++renders;
  if (preparing(st)) {
    waitWhilePreparing(app, request, st).then(async (r) => {
      if (mine !== renders) return;
      if (r.status === 200) render(r.data);
      else await cannotGo("/api/state", r);
    });
    return;
  }
  const bar = document.getElementById("progress-bar");
  // within a closed-loop page the teacher's own progress moves the bar with every item
  const within = st.step.kind === "closed_loop" && typeof st.step.progress === "number"
    ? Math.min(1, Math.max(0, st.step.progress)) : 0;
  if (bar) {
    bar.style.width = `${Math.round((100 * (st.step_index + within)) / Math.max(1, st.n_steps - 1))}%`;
  }
  app.dataset.step = st.step.kind;
  app.dataset.stepIndex = String(st.step_index);
  const page = pages[st.step.kind];
  if (!page) { showError(`Unknown page ${st.step.kind}`); return; }
  page(st);
  window.scrollTo(0, 0);
}

async function refresh() {
  const r = await request("GET", "/api/state");
  if (r.status !== 200) { await cannotGo("/api/state", r); return false; }
  render(r.data);
  return true;
}

// The PID already has a session and this browser cannot prove it is the one that started
// it (no stored token, another Prolific SESSION_ID): the server sent no token.
function showElsewhere(detail) {
  app.dataset.step = "elsewhere";
  fill(app, h("h1", { text: "Study already in progress" }), h("p", { id: "elsewhere",
    text: detail || "This study is already in progress in another browser." }));
}

// The study cannot go on from here (no session, a changed study, a damaged link): report
// it and say so plainly.
async function cannotGo(path, r) {
  keyHandler = null;
  fill(app, h("h1", { text: "The study cannot continue" }));
  showError(plainMessage(r.data));
  await report(path, r);
}

// Shown while requests are being retried; the page itself stays usable.
onTrouble((on) => {
  const box = document.getElementById("net-status");
  if (box) box.hidden = !on;
});

async function main() {
  const q = new URLSearchParams(window.location.search);
  const body = { prolific_pid: q.get("PROLIFIC_PID"), study_id: q.get("STUDY_ID"),
    session_id: q.get("SESSION_ID"), mode: q.get("mode"), token: getToken() };
  const r = await request("POST", "/api/session", body);
  if (r.status === 409 && r.data.error === "session_elsewhere") { showElsewhere(r.data.detail); return; }
  if (r.status !== 200) { await cannotGo("/api/session", r); return; }
  setToken(r.data.token);
  sessionStorage.setItem("cfteach-token", r.data.token);
  await flushPending();
  const s = await request("GET", "/api/state");
  if (s.status !== 200) { await cannotGo("/api/state", s); return; }
  if (r.data.resumed) await post(s.data.step_index, "page_load", {});
  render(s.data);
}

main();
