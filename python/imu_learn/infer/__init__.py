"""A trained model as an artefact and its application: checkpoints (save, load, strip), the one
windowing rule, the streaming steppers, refine (files and arrays), export (TorchScript, ONNX), and
the shipped-model check."""
