"""Layer 5, the solver: the regularizer contract, the ADMM iteration on the device,
:func:`~rsocl.solver.reconstruct.reconstruct` (what a user runs) and the memory/time planner.

Imports the layers below it (common, device, model, analysis).
"""
