"""Mismatch diagnosis: general localisation and term selection, with the mechanical instance."""
from .localise import Localisation, LocaliseSettings, Mismatch, RegimeTest, ResidualSeries, localise
from .mechanical import (CANDIDATE_TERMS, Diagnosis, MechanicalDiagnosisSettings, diagnose_mechanical,
                         diagnose_mechanical_files, motion_regimes)
from .selection import (Assessment, ModelFit, Selection, SelectionSettings, TermSpec, assess, forward_select,
                        mismatch_mask, physical_violations)

__all__ = ["Localisation", "LocaliseSettings", "Mismatch", "RegimeTest", "ResidualSeries", "localise",
           "CANDIDATE_TERMS", "Diagnosis", "MechanicalDiagnosisSettings", "diagnose_mechanical",
           "diagnose_mechanical_files", "motion_regimes", "Assessment", "ModelFit", "Selection", "SelectionSettings",
           "TermSpec", "assess", "forward_select", "mismatch_mask", "physical_violations"]
