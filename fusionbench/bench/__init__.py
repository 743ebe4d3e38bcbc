"""The bench: the experiments' protocol, scenario files, the runner (batches, workers, clusters), the metrics of a run,
the regression checks against references, the conformance matrix's file and the metric features' registry."""
