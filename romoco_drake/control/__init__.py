"""Whole-body controllers as Drake LeafSystems."""
