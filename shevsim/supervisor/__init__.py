"""Supervisory power management: linear MPC (seed Sec. 5.2.2, App. C) and a rule-based baseline."""
