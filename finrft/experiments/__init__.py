"""The experiments: one module each, holding its model, trial, summary text and command-line flags."""
