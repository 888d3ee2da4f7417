"""HDF5 content that reads nothing but its own file: the one check every reader of a dataset makes.

HDF5 can make a file read other files: an external link (`h5py.ExternalLink`, a group or dataset in
another file), a dataset with external storage (its bytes kept in any raw file, `/home/me/secret.bin`
say) and a virtual dataset (its rows taken from datasets in other files). Read through, a stranger's
dataset would copy a local file into every export (`export --to npz` its bytes, `merge` the
reference). The only such link a dataset of ours has is a collector's index linking each demo to its
file in `episodes/` (`Dataset.demo` checks where that leads); everything else of the kind is refused.
"""

from __future__ import annotations

from typing import Any

import h5py

from fetch.errors import OutsideError


def check_sealed(group: h5py.Group, where: str, links_in: str | None = None) -> None:
    """OutsideError naming `where` (the file, the demo) and the member if anything below `group` reads
    another file: an external link, a dataset with external storage, a virtual dataset. External links
    directly in the member `links_in` ("data": an index's links to its demo files) are let through, to
    be checked where they are followed (`Dataset.demo`); no link is followed here."""
    found: list[str] = []

    def visit(name: str, link: Any) -> None:
        if found:
            return
        if isinstance(link, h5py.ExternalLink):
            if links_in is not None and name.rpartition("/")[0] == links_in:
                return
            found.append(f"{name} is an external link to {link.filename}:{link.path}")
        elif isinstance(link, h5py.HardLink):
            item = group.get(name)
            if isinstance(item, h5py.Dataset):
                if item.is_virtual:
                    found.append(f"{name} is a virtual dataset (its rows come from other files)")
                elif item.external:
                    files = sorted({str(f[0]) for f in item.external})
                    found.append(f"{name} keeps its data in another file ({', '.join(files)})")

    group.visititems_links(visit)
    if found:
        raise OutsideError(f"{where}: {found[0]}; a dataset's arrays must be stored in its own files, so it is "
                           "refused (nothing outside its folder is read)")
