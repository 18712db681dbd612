"""Applications: the ``eigview`` command, the experiments, the demo, ONNX inference
(``predict``) and the benchmarks. Nothing below imports from here."""
