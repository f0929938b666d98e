// SVG drawing of a gridworld state in the study's visual language (study-platform.md §1.5).
// Coordinates are 1-based with y up; every cell is a <rect data-x data-y data-kind>.
const NS = "http://www.w3.org/2000/svg";
export const CELL = 64;
const COLORS = {
  wall: "#2E3131", agent: "#628dbe", trail: "#677387", mud: "#E0E644", path: "#DCBBFC",
  tile_a: "#C88B66", tile_b: "#588B66", goal: "#A9A9A9", destination: "#B395C4",
  station: "#58895F", package: "#B395C4", skateboard: "#E8963A", pentagon: "#58895F",
  diamond: "#E8963A", star: "#9B6FC4",
};

function el(name, attrs = {}, parent = null) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

function origin(layout, [x, y]) {
  return [(x - 1) * CELL, (layout.height - y) * CELL];
}

function polygon(cx, cy, r, n, rot, attrs, parent) {
  const pts = [];
  for (let i = 0; i < n; i++) {
    const a = rot + (2 * Math.PI * i) / n;
    pts.push(`${(cx + r * Math.cos(a)).toFixed(1)},${(cy + r * Math.sin(a)).toFixed(1)}`);
  }
  return el("polygon", { points: pts.join(" "), ...attrs }, parent);
}

function star(cx, cy, r, attrs, parent) {
  const pts = [];
  for (let i = 0; i < 10; i++) {
    const rr = i % 2 ? r * 0.45 : r;
    const a = -Math.PI / 2 + (Math.PI * i) / 5;
    pts.push(`${(cx + rr * Math.cos(a)).toFixed(1)},${(cy + rr * Math.sin(a)).toFixed(1)}`);
  }
  return el("polygon", { points: pts.join(" "), ...attrs }, parent);
}

// Draw an object of a given style centred in a box (x0, y0, size).
function shape(style, x0, y0, size, parent, extra = {}) {
  const c = COLORS[style] || "#888";
  const cx = x0 + size / 2, cy = y0 + size / 2, r = size * 0.32;
  const a = { fill: c, "data-kind": style, ...extra };
  switch (style) {
    case "package": return el("circle", { cx, cy, r, ...a }, parent);
    case "skateboard":
      return el("rect", { x: x0 + size * 0.15, y: y0 + size * 0.38, width: size * 0.7,
        height: size * 0.24, rx: size * 0.1, ...a }, parent);
    case "pentagon": return polygon(cx, cy, r, 5, -Math.PI / 2, a, parent);
    case "station": return polygon(cx, cy, r, 6, 0, a, parent);
    case "diamond": return polygon(cx, cy, r, 4, -Math.PI / 2, a, parent);
    case "star": return star(cx, cy, r * 1.1, a, parent);
    case "destination":
      return el("rect", { x: x0 + size * 0.3, y: y0 + size * 0.3, width: size * 0.4,
        height: size * 0.4, ...a }, parent);
    default: return el("circle", { cx, cy, r, ...a }, parent);
  }
}

function region(style, x0, y0, parent, extra) {
  const a = { "data-kind": style, ...extra };
  const c = COLORS[style] || "#ddd";
  if (style === "tile_a") {
    return el("rect", { x: x0 + 12, y: y0 + 12, width: CELL - 24, height: CELL - 24,
      fill: c, ...a }, parent);
  }
  if (style === "tile_b") {
    return el("circle", { cx: x0 + CELL / 2, cy: y0 + CELL / 2, r: CELL * 0.3, fill: "none",
      stroke: c, "stroke-width": 8, ...a }, parent);
  }
  return el("rect", { x: x0, y: y0, width: CELL, height: CELL, fill: c, ...a }, parent);
}

export function drawGrid(layout, state, opts = {}) {
  const W = layout.width * CELL, H = layout.height * CELL;
  const svg = el("svg", { viewBox: `0 0 ${W} ${H}`, width: W, height: H, class: "grid",
    role: "img", "aria-label": opts.label || "game board" });
  el("rect", { x: 0, y: 0, width: W, height: H, fill: "#fff" }, svg);
  for (const m of layout.markers || []) {
    const [x0, y0] = origin(layout, m.cell);
    if (m.style === "goal") region("goal", x0, y0, svg, { "data-marker": m.name });
  }
  for (const r of layout.regions || []) {
    for (const cell of r.cells) {
      const [x0, y0] = origin(layout, cell);
      region(r.style, x0, y0, svg, { "data-region": r.name });
    }
  }
  for (const w of layout.walls || []) {
    const [x0, y0] = origin(layout, w);
    el("rect", { x: x0, y: y0, width: CELL, height: CELL, fill: COLORS.wall,
      "data-kind": "wall" }, svg);
  }
  for (let x = 1; x <= layout.width; x++) {
    for (let y = 1; y <= layout.height; y++) {
      const [x0, y0] = origin(layout, [x, y]);
      el("rect", { x: x0, y: y0, width: CELL, height: CELL, fill: "none", stroke: "#000",
        "stroke-width": 1.5, "data-x": x, "data-y": y, "data-kind": "cell" }, svg);
    }
  }
  for (const m of layout.markers || []) {
    if (m.style === "goal") continue;
    const [x0, y0] = origin(layout, m.cell);
    shape(m.style, x0, y0, CELL, svg, { "data-marker": m.name });
  }
  for (const c of layout.consumables || []) {
    if (state[c.key]) {
      const [x0, y0] = origin(layout, c.cell);
      shape(c.style, x0, y0, CELL, svg, { "data-object": c.key });
    }
  }
  const trail = opts.trail || [];
  trail.forEach((p, i) => {
    const [x0, y0] = origin(layout, p);
    if (i === 0) {
      el("rect", { x: x0 + CELL / 2 - 8, y: y0 + CELL / 2 - 2, width: 16, height: 4,
        fill: COLORS.trail, "data-kind": "trail-start" }, svg);
    } else {
      el("circle", { cx: x0 + CELL / 2, cy: y0 + CELL / 2, r: 4, fill: COLORS.trail,
        "data-kind": "trail" }, svg);
    }
  });
  for (const cell of opts.highlight || []) {  // where two routes part (feedback page)
    const [x0, y0] = origin(layout, cell);
    el("rect", { x: x0 + 3, y: y0 + 3, width: CELL - 6, height: CELL - 6, fill: "none",
      stroke: "#c0392b", "stroke-width": 6, "stroke-dasharray": "10 5",
      "data-kind": "part" }, svg);
  }
  const cargo = layout.cargo && state[layout.cargo.key] ? state[layout.cargo.key] : null;
  if (cargo && !state.carrying) {
    const [x0, y0] = origin(layout, cargo);
    shape(layout.cargo.style, x0, y0, CELL, svg, { "data-object": layout.cargo.key });
  }
  const [ax0, ay0] = origin(layout, state.agent);
  const onCargo = cargo && !state.carrying && cargo[0] === state.agent[0] &&
    cargo[1] === state.agent[1];
  polygon(ax0 + CELL / 2, ay0 + CELL / 2 + 4, CELL * (onCargo ? 0.2 : 0.3), 3, -Math.PI / 2,
    { fill: COLORS.agent, stroke: "#fff", "stroke-width": 1.5, "data-kind": "agent",
      "data-x": state.agent[0], "data-y": state.agent[1] }, svg);
  if (cargo && state.carrying) {
    const [x0, y0] = origin(layout, cargo);
    shape(layout.cargo.style, x0 + CELL * 0.6, y0 + 2, CELL * 0.38, svg,
      { "data-object": layout.cargo.key, "data-carried": "true" });
  }
  if (opts.banner) {  // a string, or {lines: [...], tone: "fail"} (tone: a CSS class)
    const b = typeof opts.banner === "string" ? { lines: [opts.banner] } : opts.banner;
    // Bold text is about 0.62 em per character: shrink it so the longest line fits the
    // board with a margin (a 4-cell board cannot hold "Demonstration complete" at 28 px).
    const longest = Math.max(...b.lines.map((l) => l.length), 1);
    const size = Math.min(b.lines.length > 1 ? 24 : 28, (W * 0.9) / (0.62 * longest));
    const gap = size * 1.25;
    const top = H / 2 - (gap * (b.lines.length - 1)) / 2;
    el("rect", { x: 0, y: top - size * 1.1, width: W, height: gap * (b.lines.length - 1) +
      size * 1.6, class: "banner-back", "data-kind": "banner-back" }, svg);
    const t = el("text", { x: W / 2, y: top, "text-anchor": "middle",
      class: `banner${b.tone ? ` ${b.tone}` : ""}`, "data-kind": "banner",
      "font-size": size }, svg);
    b.lines.forEach((line, i) => {
      const span = el("tspan", { x: W / 2, y: top + i * gap }, t);
      span.textContent = line;
    });
  }
  return svg;
}
