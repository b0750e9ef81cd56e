"""Time is integer nanoseconds everywhere (stamps, durations); this is the one conversion constant."""

NS_PER_S = 1_000_000_000
