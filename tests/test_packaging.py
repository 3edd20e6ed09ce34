"""The package layout the design card draws: parameter files in the top-level models/ (their one source),
shipped as thermo_ddp.models; every subpackage of src/ listed in pyproject.toml (the list is explicit because
of the models/ mapping, so a new subpackage must be added there)."""
import tomllib
from importlib import resources
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_subpackage_is_listed_in_pyproject():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = {".".join(p.parent.relative_to(ROOT / "src").parts) for p in (ROOT / "src").rglob("__init__.py")}
    assert set(config["packages"]) == on_disk | {"thermo_ddp.models"}
    assert config["package-dir"]["thermo_ddp.models"] == "models"


def test_parameter_files_have_one_source_the_top_level_models_folder():
    shipped = Path(str(resources.files("thermo_ddp.models")))
    assert shipped.resolve() == (ROOT / "models").resolve() or not (ROOT / "models").exists()  # wheel: installed copy
    assert {p.name for p in shipped.glob("*.toml")} >= {"arm_left_4_joint.toml", "paderborn_pmsm.toml"}
    assert not (ROOT / "src" / "thermo_ddp" / "models").exists()  # no second copy inside the package
