"""The lab: measurements behind make bench, make demo, make stereo and the paper's claims (not installed)"""
