"""Test apparatus, not the product: the simulated robot elbow (``testbed``) with physics concealed from the
models, its three-node truths, and toy optimal-control problems (``thermal_pendulum``). Tests, studies and
benchmarks use them as oracles and plants; nothing in the core imports them."""
