"""Human body models: skeletons, anthropometry, sensor and marker placement, scaling."""
