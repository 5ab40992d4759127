"""How dead reckoning is scored against ground truth: relative pose error over n samples, the start-up
bias fit (metrics.py), and the protocol's variants and its text as every report states it
(protocol.py). Used by training's model selection and final table, evaluate, the model check and fuse."""
