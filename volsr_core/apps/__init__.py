"""The commands' back-ends: batch upscaling, the benchmark and the evaluation, above every host-free layer."""
