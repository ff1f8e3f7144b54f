"""Training data: dataset configs, camera-path videos rendered to HDF5 stores, and their manifest."""
