"""MkDocs hook: the pictures of `outputs/` that the README shows are published with the site, at
the same paths (`outputs/...`), so that the pages show the committed files themselves."""
from pathlib import Path

from mkdocs.structure.files import File

#: The committed pictures the pages show, relative to the repository's root.
PICTURES = ("outputs/circles.gif", "outputs/hexatic.gif", "outputs/eos_sweep.png",
            "outputs/melting_sweep.png", "outputs/melting_65536/reduced_pressure.png",
            "outputs/bench/intel-xeon-processor/work_precision.png",
            "outputs/bench/amd-epyc/dense.png")


def on_files(files, config):
    root = Path(config.config_file_path).parent
    for path in PICTURES:
        files.append(File(path, src_dir=str(root), dest_dir=config.site_dir, use_directory_urls=False))
    return files
