"""The docs' generated tables (tasks, observation layouts, the dataset's keys); a test holds the pages to them."""

from __future__ import annotations

import inspect

from fetch import observation as ob
from fetch.learn.recipes import task_training
from fetch.tasks import ENV_IDS, REGISTRATIONS


def _first_line(obj: object) -> str:
    return (inspect.getdoc(obj) or "").splitlines()[0].rstrip(".")


def task_table() -> str:
    """| id | goal | success | horizon | obs |, one row per registered id."""
    rows = ["| id | task | success (`info['is_success']`) | horizon | observation |",
            "|---|---|---|---|---|"]
    for reg in REGISTRATIONS:
        size = sum(p.size for p in reg.task.parts)
        rows.append(f"| `{reg.env_id}` | {_first_line(reg.task)} | {reg.task.success_rule} | "
                    f"{reg.max_episode_steps} | {size} |")
    return "\n".join(rows)


def _describe(part: ob.Part) -> str:
    comp = part.components[0]
    target = comp.reading.target
    if part.euler:
        return f"Euler angles of site `{target}` [rad]"
    kind = comp.reading.kind
    if kind == "framepos":
        return (f"position of site `{target}` minus `{comp.minus.target}` [m]" if comp.minus
                else f"position of site `{target}` [m]")
    if kind == "framelinvel":
        rel = f" minus `{comp.minus.target}`'s" if comp.minus else ""
        return f"linear velocity of site `{target}`{rel} x dt [m/step]"
    if kind == "frameangvel":
        return f"angular velocity of site `{target}` x dt [rad/step]"
    joints = ", ".join(f"`{c.reading.target}`" for c in part.components)
    return f"velocity of {joints} x dt [m/step]" if kind == "jointvel" else f"position of {joints} [m]"


def layout_tables() -> str:
    """One table per distinct observation layout, naming the ids that share it."""
    groups: dict[tuple[ob.Part, ...], list[str]] = {}
    for reg in REGISTRATIONS:
        groups.setdefault(reg.task.parts, []).append(reg.env_id)
    out = []
    for parts, ids in groups.items():
        layout = ob.layout(parts)
        out.append(f"**{', '.join(f'`{i}`' for i in ids)}** ({sum(p.size for p in parts)} numbers)\n")
        out.append("| slice | name | content |\n|---|---|---|")
        for part in parts:
            sl = layout[part.name]
            out.append(f"| {sl.start}:{sl.stop} | `{part.name}` | {_describe(part)} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def dataset_table() -> str:
    """The dataset layout (schema.py), with PickPlace-v2's sizes as the example."""
    from fetch.dataset import schema
    from fetch.dataset.demo_file import IMAGE_CHUNK

    layout = schema.Layout(obs_sizes=(("observation", 25), ("achieved_goal", 3), ("desired_goal", 3)),
                           state_size=0)
    rows = ["| key | dtype | shape | content |", "|---|---|---|---|"]
    for key, doc in schema.DATA_ATTRS:
        rows.append(f"| `data.attrs['{key}']` | | | {doc} |")
    for key, doc in schema.DEMO_ATTRS:
        rows.append(f"| `data/demo_<i>.attrs['{key}']` | | | {doc} |")
    for key, doc in schema.TOOL_ATTRS:
        rows.append(f"| `{key}` | | | {doc} |")
    for field in layout.fields() + schema.OPTIONAL_FIELDS:
        tail = ", ".join(["D" if field.path == "states" else str(n) for n in field.tail] or [])
        rows_ = "T+1" if field.extra_rows else "T"
        shape = f"({rows_}{', ' + tail if tail else ''})"
        optional = "optional: " if field in schema.OPTIONAL_FIELDS else ""
        rows.append(f"| `data/demo_<i>/{field.path}` | {field.dtype} | {shape} | {optional}{field.doc} |")
    rows.append("| `data/demo_<i>/obs/<camera>_image`, `next_obs/...` | uint8 | (T, H, W, 3) | "
                "with `--cameras` or after `render-obs`: the camera's image before / after step t; gzip-compressed, "
                f"{IMAGE_CHUNK} whole frames to an HDF5 chunk (older files: h5py's own chunks; readers read either) |")
    rows.append("| `mask/train`, `mask/valid`, `mask/failed` | bytes | (n,) | demo names: a 90/10 split of the "
                "successful demos (every 10th is valid, or as `split` drew it); kept failures |")
    return "\n".join(rows)


def training_table() -> str:
    """What `gym-fetch train --policy auto` trains on each task: its recipe (`fetch.learn.recipes`)."""
    rows = ["| id | policy | steps | ensemble | goal offsets | velocities | mirror images | chunk |",
            "|---|---|---|---|---|---|---|---|"]
    for env_id in ENV_IDS:
        t = task_training(env_id)
        chunk = "the kind's" if t.chunk is None else str(t.chunk)
        velocities = "seen" if t.velocities else "not seen"
        rows.append(f"| `{env_id}` | {t.policy} | {t.steps} | {t.members} | {'yes' if t.goal_offsets else 'no'} "
                    f"| {velocities} | {'yes' if t.mirror else 'no'} | {chunk} |")
    return "\n".join(rows)


BLOCKS = {"tasks": task_table, "layouts": layout_tables, "dataset": dataset_table, "training": training_table}
"""Generated blocks between `<!-- NAME:begin -->` and `<!-- NAME:end -->` markers."""
PAGES = {"tasks": "README.md", "layouts": "docs/tasks.md", "dataset": "docs/datasets.md",
         "training": "docs/training.md"}
"""The page (from the repository's root) that holds each block."""


def render_blocks(text: str) -> str:
    """`text` with every generated block it holds replaced by its current content."""
    for name, make in BLOCKS.items():
        begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
        head, found, rest = text.partition(begin)
        if not found:
            continue
        _, found, tail = rest.partition(end)
        if not found:
            raise ValueError(f"{begin} has no {end} after it")
        text = f"{head}{begin}\n{make().rstrip()}\n{end}{tail}"
    return text


if __name__ == "__main__":
    import pathlib
    import sys

    for page in [pathlib.Path(a) for a in sys.argv[1:]] or [pathlib.Path(p) for p in sorted(set(PAGES.values()))]:
        page.write_text(render_blocks(page.read_text()))
        print(f"updated {page}")
