"""The ground floor: errors, durations, config base, names, metrics, rate limits, Zenoh options."""
