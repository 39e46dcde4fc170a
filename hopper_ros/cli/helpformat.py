"""Help texts of every `hopper` command: defaults shown, descriptions as written.

`HelpFormatter` appends `(default: X)` to an option's help unless the help already says its default or
there is none to say (None, False, a flag). `apply(parser)` gives it to a parser and every sub-command
parser below it, so each module's `add_arguments` needs nothing for it.
"""

from __future__ import annotations

import argparse


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if ("default" in text or default is None or default is False or default == "" or default is argparse.SUPPRESS
                or isinstance(action, (argparse._StoreTrueAction, argparse._StoreConstAction, argparse._HelpAction,
                                       argparse._VersionAction))
                or not (action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE))):
            return text
        return f"{text} (default: %(default)s)" if text else "(default: %(default)s)"


def apply(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                apply(sub)
