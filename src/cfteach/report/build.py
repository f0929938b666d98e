"""Pictures + `index.html` for a set of per-domain results (see `cfteach.report`)."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")
LEVELS = ("low", "medium", "high")
CURRICULUM_SCHEMA = "cfteach.curriculum/1"
TESTS_SCHEMA = "cfteach.tests/1"

LayoutFn = Callable[[str, Mapping[str, Any]], Any]


@dataclass
class DomainResults:
    """What the report shows for one domain: a curriculum per condition and a test set."""

    curricula: dict[str, dict[str, Any]] = field(default_factory=dict)
    tests: dict[str, Any] | None = None


def _as_domain_results(name: str, value: Any) -> DomainResults:
    if isinstance(value, DomainResults):
        res = value
    elif isinstance(value, Mapping):
        unknown = set(value) - {"curricula", "tests"}
        if unknown:
            raise ValueError(f"results[{name!r}]: unknown keys {sorted(unknown)}")
        res = DomainResults(dict(value.get("curricula") or {}), value.get("tests"))
    else:
        raise TypeError(f"results[{name!r}] must be a DomainResults or a mapping")
    for cond, cur in res.curricula.items():
        where = f"results[{name!r}].curricula[{cond!r}]"
        if not isinstance(cur, Mapping) or cur.get("schema") != CURRICULUM_SCHEMA:
            raise ValueError(f"{where}: not a {CURRICULUM_SCHEMA} dict")
        if cur.get("domain") != name:
            raise ValueError(f"{where}: its domain is {cur.get('domain')!r}, not {name!r}")
        for key in ("demos", "weights", "feature_names", "final_belief"):
            if key not in cur:
                raise ValueError(f"{where}: missing key {key!r}")
    if res.tests is not None:
        where = f"results[{name!r}].tests"
        if not isinstance(res.tests, Mapping) or res.tests.get("schema") != TESTS_SCHEMA:
            raise ValueError(f"{where}: not a {TESTS_SCHEMA} dict")
        for key in ("tests", "belief", "weights", "feature_names"):
            if key not in res.tests:
                raise ValueError(f"{where}: missing key {key!r}")
    if not res.curricula and res.tests is None:
        raise ValueError(f"results[{name!r}]: nothing to report (no curricula, no tests)")
    return res


def action_specs_of(name: str, sources: Mapping[str, Any] | None = None) -> tuple[Any, ...]:
    """The domain's `ActionSpec`s (for marking `exit` / `stay` in the GIFs): from `sources`
    (a loaded `Domain` or its file) or a built-in name; () when it cannot be loaded."""
    from cfteach import domains

    src = (sources or {}).get(name, name)
    try:
        dom = src if hasattr(src, "action_specs") else domains.load(src)
    except (ValueError, OSError):
        return ()
    return tuple(dom.action_specs)


def default_layouts(
    sources: Mapping[str, Any] | None = None,
) -> LayoutFn:
    """Layouts from the domain files: `cfteach.domains.load(...)` then `.instance(env_index)`.

    `sources` maps a domain name to a loaded `Domain` or to its file (user domains, whose
    name is not something `load` can find); other names are loaded as built-ins."""
    from cfteach import domains
    from cfteach.render import layout_from_instance

    loaded: dict[str, Any] = {}
    cache: dict[tuple[str, int], Any] = {}
    sources = dict(sources or {})

    def layout(domain: str, demo: Mapping[str, Any]) -> Any:
        if domain not in loaded:
            src = sources.get(domain, domain)
            loaded[domain] = src if hasattr(src, "instance") else domains.load(src)
        key = (domain, int(demo["env_index"]))
        if key not in cache:
            cache[key] = layout_from_instance(loaded[domain].instance(key[1]))
        return cache[key]

    return layout


def feature_labels(name: str, names: Sequence[str],
                   sources: Mapping[str, Any] | None = None) -> list[str]:
    """The domain file's feature labels ("Mud", "Battery") for people, in the order of
    `names`; the names themselves when the domain cannot be loaded or does not match."""
    from cfteach import domains

    src = (sources or {}).get(name, name)
    try:
        dom = src if hasattr(src, "feature_labels") else domains.load(src)
    except (ValueError, OSError):
        return list(names)
    if list(dom.feature_names) != list(names):
        return list(names)
    return list(dom.feature_labels)


def plural(n: Any, word: str) -> str:
    """"1 action", "2 actions" (the word's plural is word + "s")."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def write_results(out_dir: str | Path, results: Mapping[str, Any]) -> list[Path]:
    """Write `<out>/<domain>/<condition>.json` and `<out>/<domain>/tests.json`."""
    out = Path(out_dir)
    written = []
    for name, value in results.items():
        res = _as_domain_results(name, value)
        ddir = out / name
        ddir.mkdir(parents=True, exist_ok=True)
        for cond, cur in res.curricula.items():
            written.append(_dump(ddir / f"{cond}.json", cur))
        if res.tests is not None:
            written.append(_dump(ddir / "tests.json", res.tests))
    return written


def _dump(path: Path, data: Mapping[str, Any]) -> Path:
    path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return path


RUN_FILE = "run.json"
RUN_SCHEMA = "cfteach.run/1"


def write_run(out_dir: str | Path, meta: Mapping[str, Any]) -> Path:
    """Record how a results folder was made (domain order, profile, seed, seconds)."""
    from cfteach import __version__

    return _dump(Path(out_dir) / RUN_FILE, {"schema": RUN_SCHEMA, "version": __version__, **meta})


def load_meta(out_dir: str | Path) -> dict[str, Any]:
    """`run.json` of a results folder (without its schema tag), or {} if there is none."""
    path = Path(out_dir) / RUN_FILE
    if not path.is_file():
        return {}
    data = json.loads(path.read_text(encoding="utf-8"))
    if data.get("schema") != RUN_SCHEMA:
        raise ValueError(f"{path}: not a {RUN_SCHEMA} file")
    return {k: v for k, v in data.items() if k != "schema"}


def load_results(out_dir: str | Path) -> dict[str, DomainResults]:
    """Read back what `write_results` wrote (every domain folder with JSON files), in the
    domain order recorded in `run.json` when there is one."""
    out = Path(out_dir)
    results: dict[str, DomainResults] = {}
    order = {name: i for i, name in enumerate(load_meta(out).get("domains", []))}
    dirs = sorted(
        (p for p in out.iterdir() if p.is_dir()),
        key=lambda p: (order.get(p.name, len(order)), p.name),
    )
    for ddir in dirs:
        res = DomainResults()
        for path in sorted(ddir.glob("*.json")):
            data = json.loads(path.read_text(encoding="utf-8"))
            if data.get("schema") == CURRICULUM_SCHEMA:
                res.curricula[data["condition"]] = data
            elif data.get("schema") == TESTS_SCHEMA:
                res.tests = data
        if res.curricula or res.tests is not None:
            results[ddir.name] = res
    if not results:
        raise ValueError(f"{out}: no curriculum or test JSON files found in its domain folders")
    return results


def _fmt_env(demo: Mapping[str, Any]) -> str:
    return "".join(str(int(b)) for b in demo.get("env_code", []))


def _progress(total: int, enabled: bool | None, desc: str) -> Any:
    from tqdm.auto import tqdm

    if enabled is None:
        enabled = sys.stderr.isatty()
    return tqdm(total=total, desc=desc, disable=not enabled, file=sys.stderr, leave=False)


def build_report(
    out_dir: str | Path,
    results: Mapping[str, Any],
    *,
    layouts: LayoutFn | None = None,
    meta: Mapping[str, Any] | None = None,
    sphere_resolution: int = 60,
    gif_cell_px: int = 48,
    test_cell_px: int = 36,
    progress: bool | None = None,
) -> Path:
    """Draw every picture and write `<out_dir>/index.html`; return the HTML file's path.

    `results` maps a domain name to `{"curricula": {condition: curriculum_dict},
    "tests": tests_dict}` (or a `DomainResults`). `layouts(domain, demo)` gives the grid
    `Layout` of a demonstration; by default it is read from the domain files by name.
    """
    import jinja2

    from cfteach.render import belief as bel
    from cfteach.render import save_demo
    from cfteach.render.belief_slice import belief_picture

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    checked = {name: _as_domain_results(name, value) for name, value in results.items()}
    if not checked:
        raise ValueError("results is empty: nothing to report")
    layout_of = layouts or default_layouts((meta or {}).get("domain_files"))
    started = time.perf_counter()
    meta = dict(meta or {})
    for key in ("profile", "seed"):
        values = {cur.get(key) for r in checked.values() for cur in r.curricula.values()} | (
            {r.tests.get(key) for r in checked.values() if r.tests is not None}
        )
        if key not in meta and len(values) == 1:
            meta[key] = values.pop()

    n_pictures = sum(
        sum(len(c["demos"]) + 1 for c in r.curricula.values())
        + (1 if r.curricula else 0)
        + (sum(len(v) + 1 for v in r.tests["tests"].values()) if r.tests else 0)
        for r in checked.values()
    )
    bar = _progress(n_pictures, progress, "report pictures")
    domains_view = []
    summary_rows = []
    for name, res in checked.items():
        img = out / name / "img"
        img.mkdir(parents=True, exist_ok=True)
        rel = f"{name}/img"
        conds = _ordered_conditions(res.curricula)
        first = next(iter(res.curricula.values()), None) or res.tests or {}
        names = list(first.get("feature_names", []))
        labels = feature_labels(name, names, meta.get("domain_files"))
        label_of = dict(zip(names, labels, strict=True))
        specs = action_specs_of(name, meta.get("domain_files"))
        columns = []
        for cond in conds:
            cur = res.curricula[cond]
            demos_view = []
            for k, demo in enumerate(cur["demos"], start=1):
                file = f"{cond}-demo{k}.gif"
                save_demo(layout_of(name, demo), demo["states"], img / file, cell_px=gif_cell_px,
                          actions=demo.get("actions", ()), action_specs=specs)
                bar.update()
                demos_view.append(
                    {
                        "k": k,
                        "src": f"{rel}/{file}",
                        "env": _fmt_env(demo),
                        "gain": demo.get("knowledge_gain"),
                        "area": demo.get("belief_area_after"),
                        "masked": label_of.get(demo.get("masked_feature"),
                                               demo.get("masked_feature")),
                        "n_actions": len(demo.get("actions", [])),
                        "reward": demo.get("reward"),
                        "actions": " ".join(demo.get("actions", [])),
                    }
                )
            sphere = f"{cond}-belief.png"
            fig = belief_picture(cur["final_belief"]["constraints"], data=cur, labels=labels,
                                 title=f"{cond}: final belief", resolution=sphere_resolution)
            bel.save_figure(fig, img / sphere)
            bar.update()
            area = cur["final_belief"].get("area")
            columns.append(
                {
                    "condition": cond,
                    "json": f"{name}/{cond}.json",
                    "sphere": f"{rel}/{sphere}",
                    "demos": demos_view,
                    "final_area": area,
                }
            )
            summary_rows.append(
                {
                    "domain": name,
                    "condition": cond,
                    "n_demos": len(cur["demos"]),
                    "final_area": area,
                    "total_gain": _product(d.get("knowledge_gain") for d in cur["demos"]),
                    "profile": cur.get("profile"),
                    "seed": cur.get("seed"),
                }
            )
        areas_src = None
        if res.curricula:
            fig = bel.plot_belief_areas(res.curricula, title=f"{name}: belief area")
            bel.save_figure(fig, img / "belief-areas.png")
            bar.update()
            areas_src = f"{rel}/belief-areas.png"

        tests_view = None
        if res.tests is not None:
            tests_view = _tests_view(name, res.tests, img, rel, layout_of, test_cell_px, bar)
            for level, info in tests_view["levels"].items():
                if info["tests"]:
                    fig = belief_picture(
                        res.tests["belief"]["constraints"], data=res.tests, labels=labels,
                        bec=info["tests"][0]["constraints"],
                        title=f"{level}: belief vs first test's BEC",
                        resolution=sphere_resolution,
                    )
                    file = f"test-{level}-overlap.png"
                    bel.save_figure(fig, img / file)
                    info["overlap_picture"] = f"{rel}/{file}"
                bar.update()
        every = [d for c in res.curricula.values() for d in c["demos"]]
        if res.tests is not None:
            every += [t for ts in res.tests["tests"].values() for t in ts]
        domains_view.append(
            {
                "name": name,
                "feature_names": names,
                "feature_labels": labels,
                "weights": first.get("weights", []),
                "columns": columns,
                "areas": areas_src,
                "tests": tests_view,
                "key": _legend(name, every, layout_of),
                "known": (first.get("settings") or {}).get("known"),
            }
        )
    bar.close()

    from cfteach import __version__

    env = jinja2.Environment(
        loader=jinja2.PackageLoader("cfteach.report", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"]),
        undefined=jinja2.StrictUndefined,
    )
    env.filters["num"] = _num
    env.filters["plural"] = plural
    html = env.get_template("index.html.j2").render(
        domains=domains_view,
        summary=_pivot(summary_rows),
        summary_conditions=_ordered_conditions(r["condition"] for r in summary_rows),
        test_summary=[
            {"domain": d["name"], **d["tests"]} for d in domains_view if d["tests"] is not None
        ],
        meta=meta,
        version=__version__,
        picture_seconds=time.perf_counter() - started,
        levels=LEVELS,
    )
    index = out / "index.html"
    index.write_text(html, encoding="utf-8")
    return index


def _tests_view(
    name: str,
    tests: Mapping[str, Any],
    img: Path,
    rel: str,
    layout_of: LayoutFn,
    cell_px: int,
    bar: Any,
) -> dict[str, Any]:
    from cfteach.render import save_demo

    levels: dict[str, Any] = {}
    for level in LEVELS:
        items = []
        for k, test in enumerate(tests["tests"].get(level, []), start=1):
            file = f"test-{level}-{k}.png"
            save_demo(
                layout_of(name, test), test["states"], img / file, cell_px=cell_px, still="first"
            )
            bar.update()
            items.append(
                {
                    "k": k,
                    "src": f"{rel}/{file}",
                    "env": _fmt_env(test),
                    "overlap": test.get("overlap"),
                    "reward": test.get("optimal_reward", test.get("reward")),
                    "n_actions": len(test.get("actions", [])),
                    "n_optimal": len(test.get("all_optimal_actions", []) or []),
                    "actions": " ".join(test.get("actions", [])),
                    "constraints": test.get("constraints", []),
                }
            )
        overlaps = [t["overlap"] for t in items if t["overlap"] is not None]
        levels[level] = {
            "tests": items,
            "n": len(items),
            "overlap_min": min(overlaps) if overlaps else None,
            "overlap_max": max(overlaps) if overlaps else None,
            "overlap_picture": None,
        }
    return {
        "json": f"{name}/tests.json",
        "levels": levels,
        "centres": list(tests.get("cluster_centres", [])),
        "belief_area": tests["belief"].get("area"),
        "n_excluded": len(tests.get("excluded", [])),
    }


def _legend(name: str, demos: list[Mapping[str, Any]], layout_of: LayoutFn) -> list[Any]:
    """(label, inline SVG icon) for everything the domain's pictures show, merged over the
    instances its demonstrations and tests use (so a battery seen anywhere is listed)."""
    from dataclasses import replace

    from cfteach.render.svg import legend_icons

    envs = dict.fromkeys(int(demo["env_index"]) for demo in demos)  # first-seen order
    layouts = [layout_of(name, {"env_index": e}) for e in envs]
    if not layouts:
        return []
    base = layouts[0]
    consumables = dict(base.consumables)
    for lay in layouts[1:]:
        for n, cell in lay.consumables:
            consumables.setdefault(n, cell)
    walls = frozenset().union(*(lay.walls for lay in layouts))
    merged = replace(base, walls=walls, consumables=tuple(consumables.items()))
    return legend_icons(merged)


def _ordered_conditions(conds: Iterable[str]) -> list[str]:
    """The paper's conditions in their usual order, then any others as first seen."""
    seen = list(dict.fromkeys(conds))
    return [c for c in CONDITIONS if c in seen] + [c for c in seen if c not in CONDITIONS]


def _pivot(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One summary row per domain with a cell per condition."""
    out: dict[str, dict[str, Any]] = {}
    for r in rows:
        out.setdefault(r["domain"], {"domain": r["domain"], "cells": {}})["cells"][
            r["condition"]
        ] = r
    return list(out.values())


def _product(values: Iterable[Any]) -> float | None:
    out = 1.0
    seen = False
    for v in values:
        if v is None:
            continue
        out *= float(v)
        seen = True
    return out if seen else None


def _num(value: Any, digits: int = 3) -> str:
    """Numbers for people: `digits` significant digits, em dash for missing."""
    if value is None:
        return "—"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if value != value:  # nan
        return "nan"
    return f"{value:.{digits}g}"
