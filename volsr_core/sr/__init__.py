"""The torch layer: training data (and, later, the networks). Importing it needs torch."""
from volsr_core.sr.dataset import SequenceDataset

__all__ = ["SequenceDataset"]
