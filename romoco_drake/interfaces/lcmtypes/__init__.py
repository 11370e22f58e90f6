"""LCM message definitions (*.lcm) and their lcm-gen Python bindings in ``romoco_lcm``."""
