"""What a person reads: orientation and coherence renderings with legends, plots, and the one artifact
writer that the CLI and the service share."""
