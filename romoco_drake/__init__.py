"""romoco-drake: reduced-order-model walking controllers for bipeds and humanoids on Drake."""

from pydrake.systems.framework import LeafSystem as _LeafSystem

__version__ = "0.1.0"

# At every simulator step Drake asks each system for its witness functions, and for a system
# written in Python pybind11 first looks for a Python override of DoGetWitnessFunctions. pydrake
# binds no such method, so every lookup failed with a formatted AttributeError (pybind11 caches
# only a lookup that finds a C++ function): about 28 a tick of G1's controller, 5 % of the tick's
# instructions (romoco bench realtime; callgrind, 1000 replayed ticks: 7.63 -> 7.27 G). A C++
# method under that name ends the search at the first lookup, and Drake's own default (no witness
# functions) runs as before; a system that defines DoGetWitnessFunctions still overrides it.
_LeafSystem.DoGetWitnessFunctions = _LeafSystem.GetWitnessFunctions
