"""Stations (simulated plant or LCM robot) and run monitors."""
