"""A trained model as an artefact and its application: checkpoints (save, load, strip; the IMU rate
and device they record), the one windowing rule, the streaming steppers, refine (files and arrays;
rewrite: a recording written back in its own format), the rate and device check (rates), export
(TorchScript, ONNX), and the shipped-model check."""
