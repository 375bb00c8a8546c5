"""Node plumbing shared by the freejoint nodes (parameters, throttled logs, spin loop)."""
