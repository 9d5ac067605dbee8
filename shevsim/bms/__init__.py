"""Battery management: state, parameter and power-capability estimators."""
