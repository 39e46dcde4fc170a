"""The mismatch tool (hopper diagnose): where model and recording disagree, which physics is missing."""

from .data import DiagnosisError  # noqa: F401


def diagnose_file(*args, **kwargs):
    from .api import diagnose_file as run
    return run(*args, **kwargs)
