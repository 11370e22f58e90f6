"""State estimators: station measurements to the controller plant's state."""
