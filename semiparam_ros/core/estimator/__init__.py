"""The online estimator: building it from a configuration, streaming samples, the checkpoint format."""
