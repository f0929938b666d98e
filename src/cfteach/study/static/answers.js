// The pages where the participant answers: the survey after the demonstrations, the
// test games with their confidence item, the score after a domain's tests, demographics.
import { Game } from "./game.js";
import { continueButton, count, design, fill, h, keyLegend, likert, showError } from "./ui.js";

export function surveyPage(ctx, st) {
  const { app, advance } = ctx;
  const items = st.step.items;
  const form = h("form", { id: "survey" });
  for (const [key, item] of Object.entries(items)) {
    form.appendChild(likert(key, item));
  }
  form.appendChild(h("label", { class: "comment" }, "Feel free to explain any of your " +
    "selections above if you wish:", h("textarea", { name: "comment", maxlength: "2000" })));
  const submit = continueButton("Continue", async (e) => {
    e.preventDefault();
    const fd = new FormData(form);
    if (!fd.get("informativeness") || !fd.get("mental_effort")) {
      showError("Please answer both questions.");
      return;
    }
    submit.disabled = true;
    await advance(st.step_index, "likert", { informativeness: +fd.get("informativeness"),
      mental_effort: +fd.get("mental_effort"), comment: fd.get("comment") || "" });
    submit.disabled = false;
  }, { id: "next", type: "submit" });
  form.appendChild(submit);
  fill(app, h("h1", { text: "Survey" }),
    h("p", { text: "You have viewed all of the demonstrations for this game! Please " +
      "complete the survey below." }), form);
}

export function testPage(ctx, st) {
  const { app, advance, activate } = ctx;
  const s = st.step;
  const board = h("div", { id: "board" });
  const form = h("form", { id: "confidence" }, likert("confidence", s.confidence));
  const submit = continueButton("Submit", null, { id: "next", type: "submit",
    disabled: true });
  form.appendChild(submit);
  const t0 = performance.now() - (s.elapsed_ms || 0);  // shown before a reload: keep counting
  const game = new Game(board, s.layout, s.game, { controls: s.info.controls, label: "test game",
    onEnd: () => update() });
  const update = () => {
    const chosen = new FormData(form).get("confidence");
    submit.disabled = !(game.ended && chosen);
  };
  form.addEventListener("change", update);
  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    if (!game.ended) return;
    submit.disabled = true;
    await advance(st.step_index, "test_response", { actions: game.moves,
      time_ms: Math.round(performance.now() - t0),
      confidence: +new FormData(form).get("confidence"), resets: game.resets });
  });
  fill(app,
    h("h1", { text: "Participant gameplay" }),
    h("p", { id: "trial", text: `Game ${s.trial} of ${s.n_trials}` }),
    h("p", { text: `Now it's your turn to play ${count(s.n_trials, "game")}! ` +
      "Please demonstrate how you would " +
      "complete this game's task while minimizing Chip's energy loss. You may reset at any " +
      "time before the game ends if you think you've made a mistake." }),
    h("p", { text: `Task: ${s.info.task}` }),
    h("div", { class: "play" }, board, keyLegend(s.info.controls)),
    h("p", { text: "Please answer the question below on the confidence of your gameplay " +
      "after providing your demonstration. For fun: We will let you know how well you did " +
      "at the end of all the games." }),
    form);
  activate(game);
}

export function feedbackPage(ctx, st) {
  const { app, advance } = ctx;
  const s = st.step;
  const text = s.last
    ? `You've completed all of the gameplays for the ${design(st).one ? "" : "final "}` +
      "game! If you were curious, you " +
      `got ${s.correct} out of ${s.total} games correct.`
    : `You've completed all of the gameplays for this game! If you were curious, you got ` +
      `${s.correct} out of ${s.total} games correct. Let's head over to the next one!`;
  fill(app, h("h1", { text: "Nice work!" }), h("p", { id: "score", text }),
    continueButton("Continue", () => advance(st.step_index, "continue"), { id: "next" }));
}

export function demographicsPage(ctx, st) {
  const { app, advance } = ctx;
  const s = st.step;
  const form = h("form", { id: "demographics" },
    h("label", {}, "Do you have any comments or feedback on the study?",
      h("textarea", { name: "comments", maxlength: "4000" })),
    h("label", {}, "What is your age? ", h("input", { type: "number", name: "age",
      min: "18", max: "120", required: true })),
    h("fieldset", {}, h("legend", { text: "Which of the following most accurately " +
      "describes you?" }), s.genders.map((g) => h("label", { class: "opt" },
      h("input", { type: "radio", name: "gender", value: g, required: true }), ` ${g}`))),
    h("label", {}, "What is the highest level of education you have completed? (optional) ",
      h("select", { name: "education" }, h("option", { value: "", text: "-" }),
        s.education.map((e) => h("option", { value: e, text: e })))));
  const submit = continueButton("Continue", async (e) => {
    e.preventDefault();
    if (!form.reportValidity()) return;
    const fd = new FormData(form);
    submit.disabled = true;
    await advance(st.step_index, "demographics", { age: +fd.get("age"),
      gender: fd.get("gender"), education: fd.get("education") || null,
      comments: fd.get("comments") || "" });
    submit.disabled = false;
  }, { id: "next", type: "submit" });
  form.appendChild(submit);
  fill(app, h("h1", { text: "Final questions" }),
    h("p", { text: `Congratulations on getting through ${design(st).one ? "the main game"
      : "all of the main games"}! Please ` +
      "answer the following questions, and then click 'Continue' for instructions on " +
      "compensation." }), form);
}
