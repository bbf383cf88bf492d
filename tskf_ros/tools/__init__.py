"""Command-line tools: bag plots, the sample bags and the demo's clients."""
