"""Command-line tools: bag plots, the sample bags, the demo's clients, the Foxglove bridge."""
