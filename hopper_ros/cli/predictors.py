"""`hopper predictors`: compare the stride predictors with the exact model, write a report."""

from __future__ import annotations

import sys

HELP = "compare the AAS and the corrected AAS with the exact model; write a report (markdown, PNG)"


def add_arguments(parser) -> None:
    parser.add_argument("-n", "--strides", type=int, default=2000, help="strides to draw from the thesis ranges")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", default="model.yaml", help="model parameters (config/ name or path)")
    parser.add_argument("-o", "--output", default="out/predictors", help="report folder")


def main(args) -> int:
    from hopper_ros.config.schemas import load_model
    from hopper_ros.reports.predictors import write_predictor_report
    from hopper_ros.config.schema import ConfigError

    if args.strides < 10:
        raise SystemExit("hopper predictors: --strides must be at least 10")
    try:
        params = load_model(args.model)
    except (ConfigError, FileNotFoundError) as exc:
        print(f"hopper predictors: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    path = write_predictor_report(args.output, params, args.strides, args.seed)
    print(f"report written to {path}")
    return 0
