"""The judgement: the model selection, the noise floor, degenerate data, where the gap lies."""
