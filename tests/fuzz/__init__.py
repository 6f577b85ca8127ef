"""Grammar-aware fuzzing of every transport (hardening): strategies, tests, frame grammar."""
