"""Presentation of a diagnosis (`records.Diagnosis`): the verdict, timing and location lines, markdown + PNG for
a researcher, JSON for a program."""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import numpy as np

from .data import LEAD_RESOLVED, PHASES


def _fmt(x):
    return "-" if x is None or not np.isfinite(x) else f"{x:.3g}"


def _num(x):
    return None if x is None or not math.isfinite(float(x)) else float(x)


def _finite(value):
    """JSON has no inf or nan: they become null."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def verdict(chosen: list, left: list | None = None, threshold: float = math.inf, complete=None, drifts=(),
            dependences=()) -> str:
    """The `missing:` line; a located residual that nothing explains is named as such, not hidden; with
    `complete` (`records.Completeness`) whether the accepted effects explain the mismatch or how much is left;
    a drift of a main parameter (`drift.Drift`) said with its size and rate, a dependence on the track position
    (`dependence.Dependence`) with its size and place."""
    unexplained = [loc for loc in (left or []) if loc.ratio >= threshold]
    tail = ""
    if unexplained:
        tail = ("; unexplained: " + "; ".join(loc.words() for loc in unexplained[:2])
                + " (no library effect or discovered term fits it)")
    if not chosen and not drifts and not dependences:
        if not unexplained:
            if complete is None or complete.explained:
                return "no significant mismatch"
            ratios = "/".join(f"{complete.over_floor[k]:.1f}" for k in ("E_p", "E_v", "E_t"))
            return (f"missing: something that moves the next apex (held-out E_p/E_v/E_t at {ratios} x the noise "
                    "floor) and stands out nowhere in the strides")
        path = "; it changes the path between apexes, not the next apex" if complete and complete.path_only else ""
        return ("missing: something no library effect or discovered term models, at "
                + "; ".join(loc.words() for loc in unexplained[:2]) + path)
    parts = []
    for r in chosen:
        c = r.candidate
        if c.kind == "discovered":
            text = f"{c.name}: {c.describe(r.value)}"
        else:
            text = f"{c.name} = {r.magnitude:.4g} {c.unit}".rstrip()
            text += "".join(f" ({k} {v:.4g} {u})" for k, (v, u) in c.held.items())
            text += f": {c.describe(r.value)}" if c.discovery is not None else ""     # a law of `angle`
        if r.ties:
            text += " (or " + " or ".join(t.name for t in r.ties) + ": not separable on this data)"
        parts.append(text)
    parts += [f"drift: {d.sentence()}" for d in drifts]
    parts += [f"dependence: {d.sentence()}" for d in dependences]
    if complete is not None:   # says what `tail` says, with how much is left
        tail = "; " + complete.words()
    return "missing: " + ", ".join(parts) + tail


def timing_line(data) -> str:
    """Where stance begins against the model's geometry (the held leg starts to turn before the model's leg,
    at its rest length, would reach the ground): empty when they agree."""
    lead = data.touchdown_lead
    if abs(lead) <= LEAD_RESOLVED:
        return ""
    when = "before" if lead > 0 else "after"
    return (f"events: stance begins {abs(lead) * 1e3:.1f} ms {when} the model's leg reaches the ground (median "
            "over strides): the running surface or the leg's length is not where the model has it, or the height "
            "channel lags")


def location_line(locations: list, threshold: float) -> str:
    above = [loc for loc in locations if loc.ratio >= threshold]
    if not above:
        return "location: nothing above the noise level"
    return "location: " + "; ".join(loc.words() for loc in above[:3])


def _entry(r) -> dict:
    c = r.candidate
    entry = {"name": c.name, "kind": c.kind, "family": c.family, "site": c.site, "magnitude": _num(r.magnitude),
             "unit": c.unit, "words": c.describe(r.value), "equation": c.equation}
    if c.discovery is not None:
        entry["terms"] = [{"term": key, "coefficient": coef * r.value, "unit": unit, "words": words}
                          for key, coef, words, unit in c.discovery.terms()]
    if c.held:
        entry["secondary"] = [{"name": k, "value": v, "unit": u} for k, (v, u) in c.held.items()]
    return entry


def verdict_entries(result) -> list[dict]:
    """The accepted effects as plain data (what --json writes under "verdict")."""
    out = []
    for r in result.chosen:
        c = r.candidate
        entry = _entry(r)
        entry.update({"held_out_trajectory_reduction": r.reduction,
                      "not_separable_from": [t.name for t in r.ties],
                      "look_alikes": [_entry(t) for t in r.ties],
                      "to_separate": sorted({c.separate, *(t.candidate.separate for t in r.ties)} - {""})})
        out.append(entry)
    return out


def _location_entries(locations, threshold):
    return [{"phase": loc.phase, "direction": loc.direction, "site": loc.site, "window": loc.window,
             "size": loc.size, "unit": loc.unit, "over_noise": loc.ratio, "above_noise": loc.ratio >= threshold,
             "basis": loc.basis}
            for loc in locations]


def write_json(result, path: Path) -> Path:
    threshold = result.settings.locate_threshold
    entries = verdict_entries(result)
    # held-out next-apex errors before and after each accepted effect (cumulative)
    before = result.before
    for entry, r in zip(entries, result.chosen):
        entry["held_out_before"] = before.as_dict()
        entry["held_out_after"] = r.errors.as_dict()
        before = r.errors
    doc = {"recording": str(result.data.rec.source), "strides": len(result.data.strides),
           "verdict": entries, "summary": result.verdict,
           "location": _location_entries(result.location, threshold),
           "held_out": {"before": result.before.as_dict(), "after": result.after.as_dict()},
           "stance_begins_before_model_touchdown_s": result.data.touchdown_lead,
           "completeness": result.completeness.as_dict() if result.completeness else None,
           "drift": [d.as_dict() for d in result.drifts],
           "dependence": [d.as_dict() for d in result.dependences],
           "model_effects": result.model_effects}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_finite(doc), indent=2, allow_nan=False), encoding="utf-8")
    return path


def _located_panel(ax, result) -> None:
    """Per site, the located residual over the noise level before and after the accepted effects (the strongest
    location of each site and basis), against the threshold."""
    rows = {}
    for column, locations in enumerate((result.location, result.residual_location)):
        for loc in locations:
            key = f"{loc.phase}, {loc.direction}" + ("" if loc.basis == "force" else f" ({loc.basis})")
            rows.setdefault(key, [0.0, 0.0])[column] = max(rows.get(key, [0.0, 0.0])[column], loc.ratio)
    names = sorted(rows, key=lambda k: -max(rows[k]))[:8]
    x = np.arange(len(names))
    ax.bar(x - 0.2, [rows[n][0] for n in names], 0.4, color="tab:red", label="model")
    ax.bar(x + 0.2, [rows[n][1] for n in names], 0.4, color="tab:blue", label="model + accepted effects")
    ax.axhline(result.settings.locate_threshold, color="black", lw=0.8, ls="--", label="threshold")
    ax.set_xticks(x, [textwrap.fill(n, 16) for n in names], fontsize=7)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(0.0, 2.0 * max([result.settings.locate_threshold] + [max(rows[n]) for n in names]))
    ax.set_ylabel("located residual / noise level")
    ax.legend(loc="upper right", fontsize=7)


def write_report(result, out: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    data = result.data
    s, rec = data.strides, data.rec
    fig = plt.figure(figsize=(9, 12))
    grid = fig.add_gridspec(4, 1, height_ratios=(1, 1, 1, 0.9))
    axes = [fig.add_subplot(grid[0])]
    axes += [fig.add_subplot(grid[k], sharex=axes[0]) for k in (1, 2)]
    for i, (sb, sa) in enumerate(zip(result.base_series, result.after_series)):
        a, b = int(s.start[i]), int(s.stop[i])
        tk = rec.t[a:b] - s.touchdown_time[i]
        for ax, v in zip(axes, ("y", "z", "theta")):
            ax.plot(tk * 1e3, sb[v][0] * 1e3, color="tab:red", lw=0.5, alpha=0.5, label="model" if i == 0 else None)
            if result.chosen:
                ax.plot(tk * 1e3, sa[v][1] * 1e3, color="tab:blue", lw=0.5, alpha=0.5,
                        label="model + accepted effects" if i == 0 else None)
    for ax, v in zip(axes, ("y", "z", "theta")):
        sig = data.sigma[v] * 1e3
        ax.axhspan(-3 * sig, 3 * sig, color="grey", alpha=0.3, label="+-3 noise std")
        ax.set_ylabel(f"{v} residual [{'mrad' if v == 'theta' else 'mm'}]")
    axes[0].legend(loc="upper left", fontsize=8)
    axes[2].set_xlabel("time from touchdown [ms]")
    _located_panel(fig.add_subplot(grid[3]), result)
    fig.suptitle(textwrap.fill(f"{Path(rec.source).name}: {result.verdict}", 120), fontsize=8, ha="left", x=0.02)
    fig.tight_layout()
    png = out / "diagnosis.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)

    threshold = result.settings.locate_threshold
    lines = [f"# Diagnosis of {rec.source}", "", f"**{result.verdict}**", "",
             f"{len(s)} strides ({'labelled' if s.labelled else 'phases detected'}); noise std estimated from flight "
             f"samples: y {data.sigma['y'] * 1e3:.3f} mm, z {data.sigma['z'] * 1e3:.3f} mm, "
             f"theta {data.sigma['theta'] * 1e3:.3f} mrad.", "",
             "## 1. Where the model and the recording differ", "",
             location_line(result.location, threshold), "", timing_line(data), "",
             "By force: residual forces at the measured state (recording minus model, the smoothing's bias removed "
             "with a clean twin of the recording made by the model), against what noise alone produces (a noisy "
             "twin). By fit: the change acting at the site that, fitted on training strides, removes most of the "
             "held-out residual (its t over strides, scaled so that the guard's t is the threshold):", "",
             "| phase | direction | basis | window | size | over noise |", "|---|---|---|---|---|---|"]
    for loc in result.location:
        lines.append(f"| {loc.phase} | {loc.direction} | {loc.basis} | {loc.window} | {loc.size:+.3g} {loc.unit} "
                     f"| {loc.ratio:.1f} |")
    lines += ["", "## 2. Candidates (held-out ranking)", ""]
    for k, ranking in enumerate(result.rounds):
        lines += [f"Round {k + 1}" + (" (on top of the effects accepted before)" if k else "") + ":", "",
                  "| candidate | kind | fitted magnitude | held-out SSE reduction | t | held-out E_p/E_v/E_t % | verdict |",
                  "|---|---|---|---|---|---|---|"]
        for r in ranking[:12]:
            c = r.candidate
            e = r.errors
            mag = c.describe(r.value) if c.kind == "discovered" else f"{r.magnitude:.4g} {c.unit}"
            why = "accepted" if r.significant else "; ".join(r.rejected)
            lines.append(f"| {c.name} | {c.kind} | {mag} | {100 * r.reduction:.1f} % | {r.t:.1f} | "
                         f"{e.E_p:.2f}/{e.E_v:.2f}/{e.E_t:.2f} | {why} |")
        lines.append("")
    for entry in verdict_entries(result):
        lines += [f"**{entry['name']}** ({entry['kind']}, {entry['site']}): {entry['words']}"
                  + (f"; law {entry['equation']}" if entry["equation"] else "")]
        if entry["not_separable_from"]:
            lines += [f"Not separable on this data from {', '.join(entry['not_separable_from'])}; to separate them: "
                      + "; ".join(entry["to_separate"]) + "."]
        lines.append("")
    lines += ["## 3. The model with the accepted effects", "", "RMS residual per phase before -> after (m, m, rad):", "",
              "| phase | y | z | theta |", "|---|---|---|---|"]
    for ph in PHASES:
        b, a = result.before_phase[ph], result.after_phase[ph]
        lines.append(f"| {ph} | " + " | ".join(f"{_fmt(b[v])} -> {_fmt(a[v])}" for v in ("y", "z", "theta")) + " |")
    bf, af = result.before, result.after
    lines += ["", "Held-out next-apex errors (magnitudes fitted without the stride's fold):", "",
              "| | E_p % | E_v % | E_t % |", "|---|---|---|---|",
              f"| model | {bf.E_p:.3f} | {bf.E_v:.3f} | {bf.E_t:.3f} |",
              f"| model + accepted | {af.E_p:.3f} | {af.E_v:.3f} | {af.E_t:.3f} |"]
    if result.completeness is not None:
        fl = result.completeness.floor
        lines += [f"| noise floor (a model without mismatch on these strides) | {fl.E_p:.3f} | {fl.E_v:.3f} | "
                  f"{fl.E_t:.3f} |", "", "Completeness: " + result.completeness.words() + "."]
    lines += ["",
              "After the accepted effects: " + location_line(result.residual_location, threshold), "",
              "![residuals](diagnosis.png)", ""]
    md = out / "diagnosis.md"
    md.write_text("\n".join(lines), encoding="utf-8")
    return md
