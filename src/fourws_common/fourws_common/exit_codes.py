"""Exit codes of fourws processes (nodes and the ``fourws`` command), one meaning each.

A launch file or a script can tell a good run from a failed one by the plant's (or
``fourws run``'s) exit status alone (docs/graph.md, "Lifecycle and bad input"):

====  ===============  ==================================================================
code  name             meaning
====  ===============  ==================================================================
0     COMPLETED        the scenario ran to its end; a node stopped by SIGINT/SIGTERM
1     ERROR            an unexpected error (a node died, a run could not be scored)
2     BAD_CONFIG       a bad parameter, argument or input file (nothing was run)
3     ABORTED          the run was aborted: the car left the road or spun
4     TIMEOUT          the run ended because commands did not arrive in time
130   INTERRUPTED      the plant was stopped (SIGINT/SIGTERM) before its run ended
====  ===============  ==================================================================
"""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    COMPLETED = 0
    ERROR = 1
    BAD_CONFIG = 2
    ABORTED = 3
    TIMEOUT = 4
    INTERRUPTED = 130


#: Exit codes with which a plant process ends a run normally (a result, not a crash).
RUN_END_CODES = frozenset({ExitCode.COMPLETED, ExitCode.ABORTED, ExitCode.TIMEOUT,
                           ExitCode.INTERRUPTED})


def describe(code: int) -> str:
    """``'3 (ABORTED)'`` for a known code, the number alone otherwise (negative: signal)."""
    try:
        return f"{code} ({ExitCode(code).name})"
    except ValueError:
        return f"{code} (killed by signal {-code})" if code < 0 else str(code)
