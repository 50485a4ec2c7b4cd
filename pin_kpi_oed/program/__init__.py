"""From a design to a measurement program: move times, safe transitions, ordering, robot-program export."""
