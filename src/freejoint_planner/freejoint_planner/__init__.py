"""freejoint planner: singularity-checked circle plans streamed on the control grid."""
