"""The HCI 4D Light Field Benchmark: what lfbench knows of its layout and protocol (the dataset adapter
``hci``, the scene reader, parameters.cfg, the writer of scene folders). The generic data code
(lfbench.data.scene, .dataset, .pattern) names none of its files."""

from lfbench.data.hci.dataset import HCI_BORDER_PX, HCI_HIGHRES_SCENES, HCI_PROTOCOL, HCIDataset
from lfbench.data.hci.params import SceneParameters, read_parameters
from lfbench.data.hci.scene import CATEGORIES, SPLITS, HCIScene, discover
from lfbench.data.hci.write import write_hci_scene

__all__ = ["HCIDataset", "HCI_PROTOCOL", "HCI_HIGHRES_SCENES", "HCI_BORDER_PX", "HCIScene", "SceneParameters",
           "read_parameters", "CATEGORIES", "SPLITS", "discover", "write_hci_scene"]
