"""Engine 3: the line delay from the bands of a flickering light (the LED method Oth et al. 2013 compare against)."""
