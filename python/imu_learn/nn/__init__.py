"""torch: the refiner model, its losses, and differentiable SO(3), integration and covariance.
Importing a submodule imports torch; this package's ``__init__`` does not, and ``nn.config`` holds
the torch-free dataclasses."""
