"""Engine 3: the line delay from the bands of a flickering light (the LED method Oth et al. 2013 compare against).

The front door is pipeline.estimate_line_delay_flicker with options.FlickerOptions; it returns a
FlickerRun with the result, the verdict and .write(out_dir) (docs/formulation.md §12)."""
