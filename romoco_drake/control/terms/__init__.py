"""The TSC-QP's terms: each cost or constraint a small class with its settings, stacked by
:class:`~romoco_drake.control.tscqp.TscQp` (the interface: :mod:`.term`)."""
