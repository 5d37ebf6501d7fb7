"""Pure helpers that import nothing else of the package: rotations and quaternions, mass
properties, small linear algebra on casadi symbols, beam shapes, the compile cache, and physical
constants. Every other folder may import from here."""
