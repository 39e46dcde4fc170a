"""Plant B: an independent TD-SLIP hopper simulator used as a blind judge.

Shares no code with the rest of the repository (see README.md).
"""
