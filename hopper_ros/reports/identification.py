"""Report: parameter identification and validation of the predictors (chapter 4).

Markdown with Table 4.1 (parameters, mean and std over the folds) and Table 4.2 (train and
test E_p, E_v, E_t) per predictor, the AAS's bias against the exact model, the identifiability
analysis, the ground reaction forces of section 4.4; PNG plots: a stride against its
predictions (Fig 4.6), the held-out error histograms, the virtual footfalls (Figs 4.8, 4.9).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hopper_ros.identification.crossval import (DESCRIPTIONS, SYMBOLS, UNITS, format_error_table,  # noqa: E402
                                                format_parameter_table)
from hopper_ros.identification.grf import kalman_smooth  # noqa: E402
from hopper_ros.identification.identifiability import scale_invariance  # noqa: E402
from hopper_ros.physics.exact import simulate_stride  # noqa: E402
from hopper_ros.physics.trajectory import predicted_trajectory  # noqa: E402

LABELS = {"aas": "AAS (thesis's predictor)", "corrected": "corrected AAS", "exact": "exact model",
          "lanes": "laws with effects (lanes)"}
THESIS_TABLE_4_2 = {"E_p": ("5.250 ±0.549", "5.163 ±0.173"), "E_v": ("5.632 ±1.372", "5.535 ±0.173"),
                    "E_t": ("2.929 ±0.849", "2.894 ±0.138")}
FIG_STRIDE = "identification_stride.png"
FIG_ERRORS = "identification_errors.png"
FIG_GRF = "grf_footfalls.png"


def _table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def identification_markdown(result, collection=None) -> list[str]:
    """The identification sections (data, tables 4.1/4.2, bias, identifiability, cost)."""
    strides, settings = result.strides, result.settings
    md = ["## Data", ""]
    if collection is not None:
        reasons = ", ".join(f"{v} {k}" for k, v in sorted(collection.discarded.items())) or "none"
        md.append(f"Simulated robot, lockstep: {collection.experiments} single-stride experiments (section 4.1) drawn from "
                  f"the thesis ranges, {len(collection.kept)} kept, the others discarded as the thesis did ({reasons}); "
                  f"{collection.messages} messages recorded in {collection.wall_time:.1f} s.")
    effects = result.recording.custom_data.get("hopper_ros.effects")
    sensors = result.recording.custom_data.get("hopper_ros.sensors")
    if effects is not None:
        md.append(f"Effects on: {effects or 'none'}; sensor noise: {sensors}.")
    rejected = {}
    for _, reason in strides.rejected:
        rejected[reason] = rejected.get(reason, 0) + 1
    md += [f"Recording `{result.recording.source}`: {len(result.recording)} samples at "
           f"{1.0 / result.recording.period:.0f} Hz; {len(strides)} apex-to-apex strides extracted "
           f"(phases {'from the recorded labels' if strides.labelled else 'detected from the kinematics'}, "
           f"inputs {'from the stride commands' if result.recording.commands else 'from the torque profile'}); "
           f"rejected: {', '.join(f'{v} {k}' for k, v in rejected.items()) or 'none'}.", ""]
    lanes_words = (" (the lanes predictor: least squares on the strides' signed errors, scored by (4.4))"
                   if "lanes" in result.cross_validations else "")
    md += [f"Fitted by Nelder-Mead minimising (4.4){lanes_words}: {', '.join(SYMBOLS[n] for n in settings.fitted)}; held: "
           + ", ".join(f"{SYMBOLS[n]} = {getattr(settings.initial, n):g} {UNITS[n]}" for n in
                       ('body_mass', 'toe_mass', 'gravity', 'stiffness', 'damping', 'flight_damping_horizontal',
                        'flight_damping_vertical', 'rest_length') if n not in settings.fitted)
           + f". Search started from {', '.join(f'{SYMBOLS[n]} = {getattr(settings.initial, n):g}' for n in settings.fitted)} "
           f"(config/identification.yaml), {settings.folds}-fold cross-validation, seed {settings.seed}.", ""]
    truth = result.truth
    for method, cv in result.cross_validations.items():
        md += [f"## {LABELS[method]}: Table 4.1, identified parameters", "",
               f"Mean and standard deviation over the {len(cv.folds)} folds' fits"
               + (" (true values: the simulated robot's)." if truth is not None else "."), "",
               format_parameter_table(cv, truth), "",
               f"### {LABELS[method]}: Table 4.2, cross-validated mean errors [%]", "",
               format_error_table(cv), "",
               f"Wall time {cv.wall_time:.1f} s ({sum(f.fit.evaluations for f in cv.folds)} cost evaluations"
               + (f", {sum(f.fit.exact_strides for f in cv.folds)} strides integrated by the exact model"
                  if method == "exact" else "")
               + (", each a lanes call with its Jacobian, the folds' calls batched together" if method == "lanes" else "")
               + ")."
               + (f" Library effects fitted with the model: {', '.join(cv.effects)} (least squares on the strides' "
                  "signed errors, docs/identification.md)." if cv.effects else ""), ""]
    md += ["The thesis's Table 4.2 on the real robot (AAS): test / training E_p "
           f"{THESIS_TABLE_4_2['E_p'][0]} / {THESIS_TABLE_4_2['E_p'][1]}, E_v {THESIS_TABLE_4_2['E_v'][0]} / "
           f"{THESIS_TABLE_4_2['E_v'][1]}, E_t {THESIS_TABLE_4_2['E_t'][0]} / {THESIS_TABLE_4_2['E_t'][1]}.", ""]
    bias = result.aas_bias_pct()
    if bias is not None:
        exact_table = result.cross_validations["exact"].parameter_table()
        aas_table = result.cross_validations["aas"].parameter_table()
        rows = []
        for name in settings.fitted:
            row = [SYMBOLS[name], f"{exact_table[name][0]:.4g}", f"{aas_table[name][0]:.4g}", f"{bias[name]:+.1f}"]
            if truth is not None:
                row.insert(1, f"{getattr(truth, name):.4g}")
                row.append(f"{100.0 * (exact_table[name][0] / getattr(truth, name) - 1.0):+.2f}")
            rows.append(row)
        header = ["parameter", "exact fit", "AAS fit", "AAS bias [%] (AAS / exact - 1)"]
        if truth is not None:
            header.insert(1, "true")
            header.append("exact fit error [%]")
        md += ["## How far the AAS's approximation biases the parameters", "",
               "Both fits on the same strides (same noise), mean over the folds. The exact model is the model the "
               "AAS approximates, so the difference is the AAS's own doing: the fit bends the parameters to make up "
               "for the approximation (the AAS's mean E_v against the exact model is ~14 % at fixed parameters, "
               "docs/predictors/predictors.md).", "", _table(header, rows), ""]
    md += _identifiability_markdown(result)
    return md


def _identifiability_markdown(result) -> list[str]:
    ident = result.identifiability
    if ident is None:
        return []
    torque_free = result.strides.subset(slice(None))
    torque_free.tau_0 = np.zeros(len(torque_free))
    invariant, _ = scale_invariance(result.cross_validations[result.best_method].mean_params(), torque_free)
    _, with_torque = scale_invariance(result.cross_validations[result.best_method].mean_params(), result.strides)
    rows = []
    for name in ident.names:
        partner, rho = ident.strongest_correlation(name)
        fitted = "yes" if name in result.settings.fitted else "held"
        rows.append([SYMBOLS[name], DESCRIPTIONS[name], fitted, f"{ident.relative_std_pct[ident.names.index(name)]:.3g}",
                     ident.verdict(name), f"{SYMBOLS[partner]} ({rho:+.2f})"])
    return ["## What the strides can identify", "",
            "Structure: in the model every force on the body is divided by m_b, so k, d, m_t and the hip torque enter "
            "only as k/m_b, d/m_b, m_t/m_b and tau/m_b. Scaling (m_b, m_t, k, d) by 1.5 changes the predicted "
            f"strides by at most {invariant:.1e} (relative) when the same strides are run without torque, and by up "
            f"to {with_torque:.0%} with their recorded torques: without torque m_b is not identifiable at all, with "
            "torque only through tau/m_b, i.e. through the torque's calibration (motor constant, gear). "
            "m_b is therefore held at its weighed value by default; fitting it (`--fit`) makes k, d and m_t follow "
            "any torque scale error.", "",
            f"Numbers (linearised at the {LABELS[result.best_method]} estimate, all seven parameters, {ident.strides} "
            f"strides, residual {ident.residual_std_pct:.3f} % per outcome): relative standard error of each "
            "parameter from the sensitivities of the strides' relative errors (4.1)-(4.3) to ln(parameter), and its "
            "strongest correlation. Below 5 %: identifiable; 5-50 %: weakly; above 50 %: not.", "",
            _table(["parameter", "description", "fitted", "relative std [%]", "verdict", "strongest correlation"], rows),
            "", f"Worst-determined combination: {ident.weakest_combination()}.", ""]


def grf_markdown(forces) -> list[str]:
    rows = []
    for profile, f in forces.items():
        early, middle, late = f.footfall_offsets("plate")
        k_early, k_middle, k_late = f.footfall_offsets("kinematic")
        rows.append([f.label, f"{f.tau_0:g}", f"{early * 1000:+.1f} / {middle * 1000:+.1f} / {late * 1000:+.1f}",
                     f"{k_early * 1000:+.1f} / {k_middle * 1000:+.1f} / {k_late * 1000:+.1f}",
                     f"{f.direction_difference_deg():.2f}"])
    return ["## Ground reaction forces (section 4.4)", "",
            "One stride per torque profile on the simulated robot (sensor noise on). Virtual footfalls: each GRF "
            "vector drawn through the centre of mass and extended to the ground; listed is where they fall relative "
            "to the toe [mm] in the first, middle and last fifth of the stance (negative: behind the toe). The "
            "kinematic GRF is m_b (a + g e_z) with the acceleration from the encoder positions (constant-acceleration "
            "Kalman model of appendix A, smoothed forward and back); the plate's is its 1 kHz samples with a moving "
            "average.", "",
            _table(["profile", "tau_0 [N m]", "plate: footfall - toe [mm]", "kinematics: footfall - toe [mm]",
                    "median angle kinematics vs plate [deg]"], rows), "",
            "Without torque the force runs along the leg and every footfall is on the toe. A hip torque adds "
            "tau/rho across the leg and moves them behind the toe; the constant torque keeps doing so until "
            "lift-off (the additional backward bias at the end of the stance the thesis notes for Fig 4.9), the ramp "
            "fades out and its footfalls converge toward the toe.", "", f"![virtual footfalls]({FIG_GRF})", ""]


# ---------------------------------------------------------------------- plots


def plot_stride(out: Path, result, index: int | None = None) -> Path:
    """Fig 4.6: one recorded stride against each predictor's trajectory (its CV-mean parameters)."""
    strides, rec = result.strides, result.recording
    if index is None:
        errors = result.cross_validations[next(iter(result.cross_validations))].test_errors().position
        index = int(np.argsort(errors)[len(errors) // 2])
    start, stop = int(strides.start[index]), int(strides.stop[index])
    t = rec.t[start:stop] - strides.apex_time[index]
    y = rec.y[start:stop] - strides.apex_y[index]
    z = rec.z[start:stop]
    _, ydot, _ = kalman_smooth(rec.t[start:stop], rec.y[start:stop], 1.3e-4, 60.0)
    _, zdot, _ = kalman_smooth(rec.t[start:stop], rec.z[start:stop], 1.3e-4, 60.0)
    inputs = [float(v[index]) for v in strides.inputs()]
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharex=True)
    panels = (("z", z, "z [m]"), ("y", y, "y [m] from the apex"), ("zdot", zdot, "z' [m/s]"), ("ydot", ydot, "y' [m/s]"))
    for ax, (_, values, label) in zip(axes.flat, panels):
        ax.plot(t, values, color="black", lw=1.6, label="recorded")
        ax.set_ylabel(label)
    for method, cv in result.cross_validations.items():
        params = cv.mean_params()
        try:
            if method == "lanes":
                trajectory = _lanes_trajectory(params, cv.mean_effects(), inputs, result.settings)
            elif method == "exact":
                trajectory = simulate_stride(params, *inputs, sample_period=1e-3).trajectory
            else:
                trajectory = predicted_trajectory(params, *inputs, method=method)
        except ValueError:
            continue
        if trajectory is None:
            continue
        for ax, (field, _, _) in zip(axes.flat, panels):
            ax.plot(trajectory.t, getattr(trajectory, field), ls="--", lw=1.1, label=LABELS[method])
    for ax in axes[1]:
        ax.set_xlabel("t [s] from the apex")
    for ax in axes.flat:
        ax.axvspan(strides.touchdown_time[index] - strides.apex_time[index],
                   strides.liftoff_time[index] - strides.apex_time[index], color="cyan", alpha=0.15)
    axes[0, 0].legend(fontsize=8)
    h, v, theta, tau_0, t_f = inputs
    fig.suptitle(f"stride {index}: apex {h:.3f} m, {v:.2f} m/s, theta_td {math.degrees(theta):.1f} deg, "
                 f"tau_0 {tau_0:.2f} N m, t_f {t_f * 1000:.0f} ms (stance shaded)")
    fig.tight_layout()
    path = out / FIG_STRIDE
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _lanes_trajectory(params, effects, inputs, settings):
    """One stride by the laws with the effects (physics.lanes), apex to next apex, for the stride figure."""
    from types import SimpleNamespace

    from hopper_ros.identification.lanesfit import with_effects
    from hopper_ros.physics.lanes import simulate_lanes

    lane = simulate_lanes(with_effects(params, effects), *(np.array([v]) for v in inputs),
                          duration=1.5, h=settings.lanes.step, sample=1e-3)
    end = lane.stride_time[0]
    if not np.isfinite(end):
        return None
    t = np.arange(lane.y.shape[1]) * 1e-3
    keep = t <= end
    return SimpleNamespace(t=t[keep], y=lane.y[0][keep], z=lane.z[0][keep], ydot=lane.ydot[0][keep],
                           zdot=lane.zdot[0][keep])


def plot_errors(out: Path, result) -> Path:
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, name, title in zip(axes, ("position", "velocity", "time"), ("E_p [%]", "E_v [%]", "E_t [%]")):
        for method, cv in result.cross_validations.items():
            values = np.maximum(getattr(cv.test_errors(), name), 1e-4)
            ax.hist(values, bins=np.logspace(-3, 2, 50), alpha=0.6, label=f"{LABELS[method]} (held out)")
        ax.set_xscale("log")
        ax.set_xlabel(title)
    axes[0].set_ylabel("strides")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path = out / FIG_ERRORS
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_footfalls(out: Path, forces) -> Path:
    fig, axes = plt.subplots(1, len(forces), figsize=(5.2 * len(forces), 4.2), sharey=True)
    for ax, (profile, f) in zip(np.atleast_1d(axes), forces.items()):
        for source, color, style in (("plate", "tab:red", "-"), ("kinematic", "tab:blue", "--")):
            feet = f.footfalls(source)
            for k in range(0, len(f.y), 4):
                if np.isfinite(feet[k]):
                    ax.plot([feet[k], f.y[k]], [0.0, f.z[k]], color=color, ls=style, lw=0.7, alpha=0.7)
        ax.plot(f.y, f.z, color="black", lw=2.0, label="centre of mass")
        ax.plot([f.toe_y], [0.0], marker="^", color="green", ms=10, label="toe")
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.plot([], [], color="tab:red", label="force plate")
        ax.plot([], [], color="tab:blue", ls="--", label="kinematics m (a + g)")
        ax.set_title(f.label, fontsize=9)
        ax.set_xlabel("y [m]")
        ax.set_aspect("equal")
    np.atleast_1d(axes)[0].set_ylabel("z [m]")
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    path = out / FIG_GRF
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(out_dir, result=None, forces=None, collection=None, title: str = "Identification and validation") -> Path:
    """Write report.md and its PNGs into `out_dir`; `result` (pipeline.Identification) and
    `forces` (profile -> grf.StanceForces) may each be None."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = [f"# {title}", "", "Chapter 4 of Orhon (2018) as a tool: `hopper report` (hopper_ros/reports/identification.py).", ""]
    if result is not None:
        md += identification_markdown(result, collection)
        plot_stride(out, result)
        plot_errors(out, result)
        md += ["## Plots", "", f"![a stride against its predictions (Fig 4.6)]({FIG_STRIDE})", "",
               f"![held-out errors]({FIG_ERRORS})", ""]
    if forces is not None:
        plot_footfalls(out, forces)
        md += grf_markdown(forces)
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n", encoding="utf-8")
    return path


__all__ = ["write_report", "identification_markdown", "grf_markdown", "plot_stride", "plot_errors", "plot_footfalls"]
