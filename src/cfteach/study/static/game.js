// A playable game from the server's transition table (the page never sees rewards, except
// the practice game's, whose energy is shown).
import { drawGrid } from "./grid.js";

// KeyboardEvent.key -> action name, for the controls of one game.
export function keyMap(controls) {
  const map = {};
  for (const c of controls) {
    map[c.key] = c.action;
    if (c.key.length === 1) {
      map[c.key.toLowerCase()] = c.action;
      map[c.key.toUpperCase()] = c.action;
    }
  }
  return map;
}

export class Game {
  constructor(host, layout, game, { controls, energy = null, onMove = null, onEnd = null,
    resetAfterEnd = false, label = "game" }) {
    Object.assign(this, { host, layout, game, controls, energy, onMove, onEnd, resetAfterEnd,
      label });
    this.keymap = keyMap(controls);
    this.host.classList.add("board");
    this.host.setAttribute("tabindex", "0");
    this.host.setAttribute("role", "group");
    this.host.setAttribute("aria-label", `${label}: use the keys in the table to play`);
    this.reset(false);
    this.resets = 0;
  }

  /** True while a key press can still change the game (a finished test game takes none:
   * its keys go back to the page, e.g. the arrows to the confidence question). */
  get listening() {
    return !this.ended || this.resetAfterEnd;
  }

  reset(count = true) {
    this.s = 0;
    this.moves = [];
    this.ended = false;
    this.banner = null;  // what the board says once the game has ended (default below)
    this.value = this.energy ? this.energy.start : null;
    this.trail = [this.game.states[0].agent];
    if (count) this.resets += 1;
    this.draw();
    if (this.onMove) this.onMove(this);
  }

  press(e) {
    if (e.key === "r" || e.key === "R") {
      if (!this.ended || this.resetAfterEnd) this.reset();
      return;
    }
    const action = this.keymap[e.key];
    if (!action || this.ended) return;
    if (this.energy && this.value <= 0) return;
    const a = this.game.actions.indexOf(action);
    if (a < 0) return;
    const nxt = this.game.next[this.s][a];
    if (nxt === this.s) return; // blocked move or no-op: ignored and not recorded
    if (this.energy) {
      const phi = this.game.phi[this.s][a];
      this.value += phi.reduce((t, f, i) => t + f * this.energy.weights[i], 0);
    }
    this.s = nxt;
    this.moves.push(action);
    const st = this.game.states[nxt];
    this.trail.push(st.agent);
    this.ended = this.game.terminal[nxt];
    this.draw();
    if (this.onMove) this.onMove(this);
    if (this.ended && this.onEnd) this.onEnd(this);
  }

  draw() {
    const st = this.game.states[this.s];
    this.host.replaceChildren(drawGrid(this.layout, st, { trail: this.trail, label: this.label,
      banner: this.ended ? (this.banner || { lines: ["Game completed!"] }) : null }));
    this.host.dataset.moves = this.moves.join(" ");
    this.host.dataset.ended = String(this.ended);
  }
}
