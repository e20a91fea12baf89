"""Floor 1, the data (docs/algorithm.md §1): procedural shapes and meshes, noise, point-file IO, and the clouds
a run uses. Imports nothing above it."""
