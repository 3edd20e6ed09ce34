"""Motor parameter files (TOML), shipped as the package data ``thermo_ddp.models``; the contract is in docs/architecture.md."""
