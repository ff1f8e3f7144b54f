"""The torch layer: network, losses, data, training, evaluation. Its modules need torch, except
:mod:`volsr_core.sr.network_config` (read by onnxruntime-only installs); nothing is imported here."""
