"""Derivative-free optimisers of a function of a parameter vector, maximising: SPSA (Spall; the thesis's, with
its modifications) and Powell (scipy's, deterministic). Generic (they see only ``f(theta) -> float``), used by
the registration, kept apart from it as ITK keeps its optimisers (``Numerics/Optimizersv4``) apart from its
registration methods and DIPY its ``core.optimize`` from ``align``."""
