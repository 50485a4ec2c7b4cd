"""Non-geometric error effects (compliance, gear harmonics, thermal, ...) that extend the geometric model."""
