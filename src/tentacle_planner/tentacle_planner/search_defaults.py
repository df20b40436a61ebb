"""
The planner's default search settings.

Here, where the command line's help reads them without loading numpy.
"""

DEFAULT_STARTS = 4
DEFAULT_ITERATIONS = 50
DEFAULT_MIN_GAIN = 0.1
"""
By default two rounds of two starts, 50 model evaluations each.

Measured on pancreatic_duct (medians of eight seeds, the dense playback aside): 1.1 s and
0.80% of L re-checked, where 100 evaluations took 1.6-1.9 s for 0.77-0.80% and 35 gave
1.15%; one round (two starts) 0.86 s but 1.01%, and 12% of L on one seed of eight; ch3_b
needed two rounds as well. With more starts (--starts) the search ends once a round lowers
the best objective by less than DEFAULT_MIN_GAIN of it (never after the first round).
"""
