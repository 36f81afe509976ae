"""A scene and the files it references, as UploadScene carries them (proto/scene_chunks.h):
the manifest first (main file, each file's path and size, the content hash), then each
file's bytes in order, a piece at most a MiB, read from disk a piece at a time.

Which files: a COLLADA scene is one file; a glTF (.gltf or .glb) names its buffers and
images by URI (data: URIs are inside the file), percent-decoded and relative to its
folder, as core/scene/gltf/gltf_document.cc reads them. An environment map travels as
.tessera-env/NAME, as `tessera submit` sends it.

The hash is proto/scene_bundle.cc's: XXH3-128 over, for the main file's name and then
each file's path and bytes, an 8-byte little-endian length and the bytes."""
import json
import os
import struct
import urllib.parse

import xxhash

from tessera._pb import tessera_pb2 as pb

CHUNK_BYTES = 1 << 20


class SceneError(ValueError):
    """A scene that cannot be sent: unreadable, or naming files outside its folder."""


def _gltf_json(path, data):
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise SceneError(f"{path}: a GLB shorter than its header")
        length, kind = struct.unpack_from("<I4s", data, 12)
        if kind != b"JSON" or 20 + length > len(data):
            raise SceneError(f"{path}: the GLB's first chunk is not its JSON")
        data = data[20:20 + length]
    try:
        return json.loads(data)
    except ValueError as e:
        raise SceneError(f"{path}: JSON: {e}") from None


def _safe_relative(rel):
    parts = rel.split("/")
    return rel and len(rel) <= 1024 and not rel.startswith("/") and "\0" not in rel and \
        not any(p in ("..", ".") for p in parts)


def scene_files(path):
    """[(path in the bundle, path on disk)], the scene file first."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        raise SceneError(f"{path}: {e.strerror}") from None
    files = [(os.path.basename(path), path)]
    if path.lower().endswith(".dae") and head != b"glTF":
        return files
    with open(path, "rb") as f:
        doc = _gltf_json(path, f.read())
    seen = set()
    for key in ("buffers", "images"):
        items = doc.get(key) if isinstance(doc, dict) else None
        for item in items if isinstance(items, list) else []:
            uri = item.get("uri") if isinstance(item, dict) else None
            if not isinstance(uri, str) or uri.startswith("data:"):
                continue
            rel = urllib.parse.unquote(uri)
            if rel in seen:
                continue
            seen.add(rel)
            if not _safe_relative(rel):
                raise SceneError(f"{path}: '{rel}' is not a path inside the scene's folder")
            files.append((rel, os.path.join(os.path.dirname(path), rel)))
    return files


class Bundle:
    """The files of a scene (and its environment map), their sizes and content hash."""

    def __init__(self, scene, env=None):
        self.files = scene_files(scene)
        if env:
            self.files.append((".tessera-env/" + os.path.basename(env), env))
        self.main_file = self.files[0][0]
        self.sizes = []
        h = xxhash.xxh3_128()

        def add(b):
            h.update(struct.pack("<Q", len(b)))
            h.update(b)

        add(self.main_file.encode())
        for rel, disk in self.files:
            try:
                size = os.path.getsize(disk)
                h.update(struct.pack("<Q", len(rel.encode())) + rel.encode() + struct.pack("<Q", size))
                with open(disk, "rb") as f:
                    got = 0
                    while chunk := f.read(CHUNK_BYTES):
                        h.update(chunk)
                        got += len(chunk)
            except OSError as e:
                raise SceneError(f"{disk}: {e.strerror}") from None
            if got != size:
                raise SceneError(f"{disk}: changed while it was read")
            self.sizes.append(size)
        self.hash = h.hexdigest()

    def manifest(self):
        m = pb.SceneManifest(main_file=self.main_file, scene_hash=self.hash)
        for (rel, _), size in zip(self.files, self.sizes):
            m.files.add(path=rel, size=size)
        return m

    def chunks(self):
        """The UploadScene stream: the manifest, then every file's pieces."""
        yield pb.SceneChunk(manifest=self.manifest())
        for i, (_, disk) in enumerate(self.files):
            with open(disk, "rb") as f:
                offset = 0
                while data := f.read(CHUNK_BYTES):
                    yield pb.SceneChunk(file=i, offset=offset, data=data)
                    offset += len(data)
            if offset != self.sizes[i]:
                raise SceneError(f"{disk}: changed while it was sent")
