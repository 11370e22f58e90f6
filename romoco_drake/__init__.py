"""romoco-drake: reduced-order-model walking controllers for bipeds and humanoids on Drake."""

__version__ = "0.1.0"
