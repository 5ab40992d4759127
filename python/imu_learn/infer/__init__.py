"""Applying a checkpoint: the one windowing rule, refine (files and arrays), export (TorchScript,
ONNX), and the shipped-model check."""
