"""Corner detectors: the rotating-star detector and the baselines it is compared against"""
