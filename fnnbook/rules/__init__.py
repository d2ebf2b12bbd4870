"""The claims' rules: small functions that turn measured numbers into checks and guarantees (issue 15)."""
