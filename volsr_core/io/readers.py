"""PLACEHOLDER: helper A replaces this file."""
SUPPORTED_EXTENSIONS = ()
def read_volume(path, series_uid=None, resample=False):
    raise NotImplementedError
