"""`hopper identify RECORDING`: parameter identification with k-fold cross-validation (section 4.2).

  hopper identify RECORDING [--predictor aas|corrected|exact|lanes ...] [--effects a,b] [--folds K]
                  [--fit a,b,...] [--config FILE] [-o DIR] [--max-strides N] [--no-progress]

RECORDING is a bag of our recorder (or `hopper collect`) or a CSV `t,y,z,theta,tau[,phase]`.
Prints Table 4.1 and Table 4.2 per predictor, the AAS's bias against the exact model when both
ran, and what the strides can identify; with -o also a report (markdown, PNG) and the
identified parameters as a model file.

--effects names library effects (`physics.effects`, e.g. leg_friction,torque_gain) fitted together
with the model parameters by the "lanes" predictor (the laws with the effects, `physics.lanes`);
it implies `-p lanes` (other -p predictors still run, without the effects). The model file then
carries them: `model: {...}` plus `effects: {name: magnitude}` (`physics.params.load_model`).
"""

from __future__ import annotations

import argparse
import sys

HELP = "identify the model parameters from a recording (Nelder-Mead on (4.4), k-fold cross-validation)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", help="bag folder, .mcap file or CSV (t,y,z,theta,tau[,phase])")
    parser.add_argument("--map", metavar="FILE", help="read another robot's bag or CSV through this mapping file "
                        "(hopper import; docs/bring_your_own_robot.md)")
    parser.add_argument("--model", metavar="FILE", help="the robot's model file: the parameters not fitted (body_mass "
                        "weighed, rest_length measured) are held at its values (default: the config's initial values)")
    parser.add_argument("-p", "--predictor", action="append", choices=("aas", "corrected", "exact", "lanes"),
                        help="predictor to identify with; repeat for several (default: config's, the AAS; "
                        "lanes with --effects)")
    parser.add_argument("--effects", metavar="A,B", help="library effects to fit with the model (implies -p lanes), "
                        "e.g. leg_friction,torque_gain")
    parser.add_argument("--folds", type=int, help="folds of the cross-validation (default: config's, 10)")
    parser.add_argument("--fit", metavar="A,B", help="parameters to fit (default: config's), e.g. "
                        "gravity,stiffness,damping,body_mass")
    parser.add_argument("--seed", type=int, help="seed of the fold split")
    parser.add_argument("--config", default="identification.yaml", help="settings (config/ name or path)")
    parser.add_argument("--max-strides", type=int, metavar="N", help="use only the first N strides")
    parser.add_argument("-o", "--output", metavar="DIR", help="write a report and the identified model file here")
    parser.add_argument("--json", metavar="FILE", help="write the identified parameters, errors and identifiability as JSON")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")


def main(args: argparse.Namespace) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("identify", [args.recording, args.config, args.map, args.model], lambda: _main(args))


def held_from_model(settings, model: str, fitted):
    """The settings' initial parameters with those not fitted taken from the robot's model file."""
    from hopper_ros.config.schemas import load_model

    robot = load_model(model)                       # its schema first: one line naming the file and the key
    return settings.initial.replace(**{name: getattr(robot, name) for name in robot.as_dict() if name not in fitted})


def _main(args: argparse.Namespace) -> int:
    from hopper_ros.identification.crossval import format_error_table, format_parameter_table
    from hopper_ros.identification.pipeline import identify
    from hopper_ros.recording.recordings import RecordingError
    from hopper_ros.identification.settings import load_settings
    from hopper_ros.recording.bag import BagError
    from hopper_ros.config.schema import ConfigError

    try:
        settings = load_settings(args.config)
        changes = {}
        if args.folds is not None:
            changes["folds"] = args.folds
        if args.seed is not None:
            changes["seed"] = args.seed
        if args.fit:
            changes["fitted"] = tuple(name.strip() for name in args.fit.split(",") if name.strip())
        if args.model:
            changes["initial"] = held_from_model(settings, args.model, changes.get("fitted", settings.fitted))
        if args.effects is not None:
            changes["effects"] = tuple(name.strip() for name in args.effects.split(",") if name.strip())
        if changes:
            settings = settings.with_changes(**changes)
        methods = tuple(dict.fromkeys(args.predictor or ([] if settings.effects else [settings.predictor])))
        if settings.effects and "lanes" not in methods:
            methods += ("lanes",)
        if settings.effects and methods != ("lanes",):
            others = ", ".join(m for m in methods if m != "lanes")
            print(f"effects {', '.join(settings.effects)} are fitted by the lanes predictor; {others} ran without them",
                  file=sys.stderr)
        from hopper_ros.cli.importer import load_for_tool

        recording = load_for_tool(args.recording, args.map, "identify")
        result = identify(recording, settings, methods, show_progress=not args.no_progress,
                          max_strides=args.max_strides)
    except (RecordingError, BagError, ValueError, FileNotFoundError) as exc:
        print(f"hopper identify: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    print(f"{len(result.strides)} strides from {result.recording.source} "
          f"({len(result.strides.rejected)} rejected); phases "
          f"{'labelled' if result.strides.labelled else 'detected'}")
    for method, cv in result.cross_validations.items():
        print(f"\n## {method}: Table 4.1 (mean ± std over {len(cv.folds)} folds)\n")
        print(format_parameter_table(cv, result.truth))
        print(f"\n## {method}: Table 4.2 (mean errors [%])\n")
        print(format_error_table(cv))
        calls = [f.fit.evaluations for f in cv.folds]
        print(f"\nwall time {cv.wall_time:.1f} s" + (f" (lanes calls per fold {min(calls)}-{max(calls)}, the folds' "
                                                     "calls batched together)" if method == "lanes" else ""))
    bias = result.aas_bias_pct()
    if bias is not None:
        print("\nAAS bias against the exact model [%]: " + ", ".join(f"{k} {v:+.1f}" for k, v in bias.items()))
    ident = result.identifiability
    print("\nidentifiability (relative standard error, linearised): "
          + ", ".join(f"{n} {s:.3g} % ({ident.verdict(n)})" for n, s in zip(ident.names, ident.relative_std_pct)))
    print("body_mass: not identifiable from strides without torque (only k/m_b, d/m_b, m_t/m_b, tau/m_b enter); "
          "held at its weighed value unless --fit names it")
    model = None
    if args.output:
        from hopper_ros.physics.params import save_params
        from hopper_ros.reports.identification import write_report

        path = write_report(args.output, result, title=f"Identification of {result.recording.source}")
        best = result.cross_validations[result.best_method]
        effects = best.mean_effects()
        model = save_params(best.mean_params(), f"{args.output}/identified_model.yaml",
                            comment=f"identified by hopper identify ({result.best_method}, "
                                    f"{settings.folds}-fold CV mean) from {result.recording.source}"
                                    + (f"\nwith the library effects {', '.join(effects)} (physics.effects; read it with "
                                       "physics.params.load_model)" if effects else ""),
                            effects=effects)
        print(f"\nreport {path}\nmodel {model}")
    if args.json:
        from hopper_ros.identification.summary import write_json

        print(f"json {write_json(result, args.json, model)}")
    return 0
