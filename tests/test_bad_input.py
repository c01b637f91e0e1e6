"""Bad inputs and faults against every stage: each test holds one defect of the "nothing lost, nothing
crashes" list fixed (data loss, signals, bad input accepted, tracebacks, misleading messages). Inputs are made
in the test and small: seconds each, but for the few marked slow.
"""

from __future__ import annotations

# ---------------------------------------------------------------- data loss: --out, superseded checkpoints

# ---------------------------------------------------------------- signals: SIGTERM, stale temporary folders

# ---------------------------------------------------------------- bad input accepted: masks

# ---------------------------------------------------------------- bad input accepted: another capture

# ---------------------------------------------------------------- tracebacks and misleading messages
