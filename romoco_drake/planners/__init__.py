"""Planner systems: foot placement over any ROM law, the hybrid ROM template, command sources."""
