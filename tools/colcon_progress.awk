# Progress of `colcon build` from its start/end events (colcon's console_start_end handler),
# for tools/setup.sh: a line per package started and per package built, "k/total".
#   colcon build ... 2>&1 | awk -v n=TOTAL -f tools/colcon_progress.awk
/^Starting >>>/ { printf "[setup] colcon: building %s\n", $3; fflush() }
/^Finished <<</ {
  c++
  took = $0
  sub(/^[^[]*/, "", took)
  printf "[setup] colcon: %d/%d built: %s %s\n", c, n, $3, took
  fflush()
}
/^(Failed|Aborted) +<<</ { printf "[setup] colcon: %s %s\n", tolower($1), $3; fflush() }
