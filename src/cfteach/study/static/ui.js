// Small DOM helpers shared by the page modules.

export function h(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "onclick") e.addEventListener("click", v);
    else if (k === "onchange") e.addEventListener("change", v);
    else if (k === "text") e.textContent = v;
    else if (v === true) e.setAttribute(k, "");
    else if (v !== false && v !== null && v !== undefined) e.setAttribute(k, v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined) continue;
    e.appendChild(typeof c === "string" ? document.createTextNode(c) : c);
  }
  return e;
}

export function continueButton(label, onclick, extra = {}) {
  return h("button", { class: "primary", onclick, ...extra }, label);
}

export function showError(msg) {
  const app = document.getElementById("app");
  const box = document.getElementById("error") || app.appendChild(h("p", { id: "error",
    class: "error", role: "alert" }));
  box.textContent = msg;
}

export function keyLegend(controls) {
  return h("table", { class: "keys" }, h("caption", { text: "Keyboard controls" }),
    h("tr", {}, h("th", { scope: "col", text: "Key" }), h("th", { scope: "col", text: "Action" })),
    controls.map((c) => h("tr", { "data-action": c.action }, h("td", { text: c.key_label }),
      h("td", { text: c.label }))),
    h("tr", {}, h("td", { text: "r" }), h("td", { text: "reset simulation" })));
}

// A Likert item: one radio group in a fieldset named by its question, so Tab reaches the
// group and the arrow keys choose within it.
export function likert(key, item) {
  return h("fieldset", { class: "likert", "data-item": key },
    h("legend", { text: item.question }),
    item.options.map((o, i) => h("label", { class: "opt" },
      h("input", { type: "radio", name: key, value: String(i + 1), required: true }), ` ${o}`)));
}

// ---- wording from the study's own design ------------------------------------------------

const WORDS = ["no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine",
  "ten", "eleven", "twelve"];

/** "three games", "one game", "13 games". */
export function count(n, noun, plural = `${noun}s`) {
  const word = n >= 0 && n < WORDS.length ? WORDS[n] : String(n);
  return `${word} ${n === 1 ? noun : plural}`;
}

/** Wording facts of the study (from the state's `design`), with the original's defaults. */
export function design(st) {
  const d = st.design || {};
  const games = d.n_games ?? 3;
  return { games, minutes: d.minutes ?? 25, tests: d.n_tests ?? null,
    // "the three games" / "the game"
    theGames: games === 1 ? "the game" : `the ${count(games, "game")}`,
    one: games === 1 };
}

/** `parent.replaceChildren(...)` without the nulls of optional parts (the DOM would show a
 * null as the text "null"). */
export function fill(parent, ...children) {
  parent.replaceChildren(...children.flat().filter((c) => c !== null && c !== undefined));
}
