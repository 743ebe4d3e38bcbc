"""The method API: the aligner protocol and base class, discovery of the methods' entry points, the input policy and
the check of a first guess, the coarse aligners, the compass loop machinery shared by the gyrocompass families, and
the claims a method makes."""
