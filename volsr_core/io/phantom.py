"""PLACEHOLDER: helper C replaces this file."""
def make_phantom(seed=0, shape=(128, 128, 128), spacing=(1.0, 1.0, 1.0)):
    raise NotImplementedError
