"""Results of a run: summary, InferenceData, posterior files, comparison of runs, software versions."""
