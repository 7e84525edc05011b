"""Reports: plots, the validation table, the files of a run."""
