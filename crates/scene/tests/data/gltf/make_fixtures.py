"""Writes the glTF fixtures of crates/scene/tests/gltf.rs with an independent
writer (pygltflib), so the importer is tested against files it did not make.

    pip install pygltflib==1.16.* && python3 make_fixtures.py

Run from this directory; the outputs are committed.
"""
import base64
import struct
import zlib

from pygltflib import (GLTF2, Accessor, AccessorSparseIndices, AccessorSparseValues, Asset, Buffer,
                       BufferView, Camera, Image, Material, Mesh, Node, PbrMetallicRoughness,
                       Perspective, Primitive, Sampler, Scene, Sparse, Texture, TextureInfo,
                       Attributes)

FLOAT, UINT = 5126, 5125
ARRAY, ELEMENTS = 34962, 34963


def png(width, height, rows):
    """A minimal RGB PNG; rows is a list of lists of (r, g, b)."""
    raw = b"".join(b"\0" + bytes(c for px in row for c in px) for row in rows)
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


class Builder:
    """One buffer of little-endian data, with views and accessors into it."""

    def __init__(self):
        self.gltf = GLTF2(asset=Asset(version="2.0", generator="pygltflib fixtures"))
        self.data = b""

    def view(self, data, target=None):
        while len(self.data) % 4:
            self.data += b"\0"
        self.gltf.bufferViews.append(BufferView(buffer=0, byteOffset=len(self.data), byteLength=len(data), target=target))
        self.data += data
        return len(self.gltf.bufferViews) - 1

    def accessor(self, values, kind):
        if kind == "SCALAR":
            data = struct.pack(f"<{len(values)}I", *values)
            view = self.view(data, ELEMENTS)
            self.gltf.accessors.append(Accessor(bufferView=view, componentType=UINT, count=len(values), type=kind))
        else:
            flat = [c for v in values for c in v]
            data = struct.pack(f"<{len(flat)}f", *flat)
            view = self.view(data, ARRAY)
            n = len(values[0])
            lo = [min(v[i] for v in values) for i in range(n)]
            hi = [max(v[i] for v in values) for i in range(n)]
            self.gltf.accessors.append(Accessor(bufferView=view, componentType=FLOAT, count=len(values), type=kind,
                                                min=lo if kind == "VEC3" else None, max=hi if kind == "VEC3" else None))
        return len(self.gltf.accessors) - 1

    def quad(self, name, material, uvs=False, normals=True):
        """A unit quad in the XY plane (facing +Z), two triangles."""
        attributes = Attributes(POSITION=self.accessor([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], "VEC3"))
        if normals:
            attributes.NORMAL = self.accessor([(0, 0, 1)] * 4, "VEC3")
        if uvs:
            # glTF's v points down the image.
            attributes.TEXCOORD_0 = self.accessor([(0, 1), (1, 1), (1, 0), (0, 0)], "VEC2")
        indices = self.accessor([0, 1, 2, 0, 2, 3], "SCALAR")
        self.gltf.meshes.append(Mesh(name=name, primitives=[Primitive(attributes=attributes, indices=indices, material=material)]))
        return len(self.gltf.meshes) - 1

    def save(self, path, embed):
        if embed:
            uri = "data:application/octet-stream;base64," + base64.b64encode(self.data).decode()
            self.gltf.buffers = [Buffer(byteLength=len(self.data), uri=uri)]
            self.gltf.save_json(path)
        else:
            self.gltf.buffers = [Buffer(byteLength=len(self.data))]
            self.gltf.set_binary_blob(self.data)
            self.gltf.save_binary(path)


def instanced():
    """One mesh, two nodes under a moved parent (instancing), and a camera."""
    b = Builder()
    b.gltf.materials.append(Material(name="paint", pbrMetallicRoughness=PbrMetallicRoughness(baseColorFactor=[0.8, 0.2, 0.1, 1.0], metallicFactor=0.0, roughnessFactor=0.5)))
    mesh = b.quad("panel", 0)
    b.gltf.cameras.append(Camera(type="perspective", name="driver", perspective=Perspective(yfov=0.8, znear=0.05, aspectRatio=1.5)))
    b.gltf.nodes = [
        Node(name="car", translation=[10.0, 0.0, 0.0], children=[1, 2]),
        Node(name="left", mesh=mesh, translation=[0.0, 2.0, 0.0]),
        # A quarter turn about +Y and twice the size: x goes to -z.
        Node(name="right", mesh=mesh, rotation=[0.0, 0.70710678, 0.0, 0.70710678], scale=[2.0, 2.0, 2.0]),
        # 2 m behind the origin, looking along -Z.
        Node(name="eye", camera=0, translation=[0.0, 1.0, 2.0]),
    ]
    b.gltf.scenes = [Scene(nodes=[0, 3])]
    b.gltf.scene = 0
    b.save("instanced.glb", embed=False)


def textured():
    """A quad with a base-colour texture of four 2×2 quadrants in a buffer view."""
    b = Builder()
    red, green, blue, yellow = (200, 30, 30), (30, 200, 30), (30, 30, 200), (220, 220, 40)
    rows = [[red, red, green, green]] * 2 + [[blue, blue, yellow, yellow]] * 2
    view = b.view(png(4, 4, rows))
    b.gltf.images.append(Image(bufferView=view, mimeType="image/png"))
    b.gltf.samplers.append(Sampler())
    b.gltf.textures.append(Texture(source=0, sampler=0))
    b.gltf.materials.append(Material(name="decal", pbrMetallicRoughness=PbrMetallicRoughness(baseColorFactor=[1, 1, 1, 1], baseColorTexture=TextureInfo(index=0), metallicFactor=0.0)))
    mesh = b.quad("sign", 0, uvs=True)
    b.gltf.nodes = [Node(name="sign", mesh=mesh)]
    b.gltf.scenes = [Scene(nodes=[0])]
    b.gltf.scene = 0
    b.save("textured.glb", embed=False)


def glass():
    """A pane with KHR_materials_ior and KHR_materials_transmission, buffers as a data URI,
    no normals (computed on import)."""
    b = Builder()
    b.gltf.extensionsUsed = ["KHR_materials_ior", "KHR_materials_transmission"]
    b.gltf.materials.append(Material(
        name="windshield",
        pbrMetallicRoughness=PbrMetallicRoughness(baseColorFactor=[0.9, 1.0, 0.9, 1.0], metallicFactor=0.0, roughnessFactor=0.0),
        extensions={"KHR_materials_ior": {"ior": 1.5}, "KHR_materials_transmission": {"transmissionFactor": 1.0}}))
    mesh = b.quad("pane", 0, normals=False)
    b.gltf.nodes = [Node(mesh=mesh)]
    b.gltf.scenes = [Scene(nodes=[0])]
    b.gltf.scene = 0
    b.save("glass.gltf", embed=True)


def draco():
    """A file that requires Draco compression (no mesh data needed to refuse it)."""
    b = Builder()
    b.gltf.extensionsUsed = ["KHR_draco_mesh_compression"]
    b.gltf.extensionsRequired = ["KHR_draco_mesh_compression"]
    b.quad("packed", None)
    b.gltf.nodes = [Node(mesh=0)]
    b.gltf.scenes = [Scene(nodes=[0])]
    b.save("draco.gltf", embed=True)


def shared_levels(b, levels, mesh):
    """Two nodes per level, each with both nodes of the next level as children, the last
    level's nodes instancing `mesh`: 2^levels instances of it from 2 * levels nodes."""
    b.gltf.nodes = []
    for level in range(levels):
        last = level == levels - 1
        children = [] if last else [2 * level + 2, 2 * level + 3]
        for side in range(2):
            b.gltf.nodes.append(Node(name=f"n{level}{'ab'[side]}", children=children, mesh=mesh if last else None,
                                     translation=[0.0, 0.0, 0.001 * side]))
    b.gltf.scenes = [Scene(nodes=[0, 1])]
    b.gltf.scene = 0


def instances_beyond_bound():
    """A quad instanced 2^21 times through 21 levels of nodes that share their children:
    more node instances than the importer's MAX_NODE_VISITS (2^20), in 8 kB of JSON."""
    b = Builder()
    b.quad("tile", None)
    shared_levels(b, 21, 0)
    b.save("instances_beyond_bound.gltf", embed=True)


def vertices_beyond_bound():
    """A mesh of 2^16 vertices (a sparse accessor: zeros and one stored value, so the file stays
    small) instanced 2^9 times: 2^25 vertices, beyond MAX_IMPORTED_VERTICES (2^24)."""
    b = Builder()
    count = 1 << 16
    index_view = b.view(struct.pack("<I", count - 1))
    value_view = b.view(struct.pack("<3f", 1.0, 1.0, 0.0))
    b.gltf.accessors.append(Accessor(componentType=FLOAT, count=count, type="VEC3", min=[0, 0, 0], max=[1, 1, 0],
                                     sparse=Sparse(count=1, indices=AccessorSparseIndices(bufferView=index_view, componentType=UINT),
                                                   values=AccessorSparseValues(bufferView=value_view))))
    b.gltf.meshes.append(Mesh(name="dust", primitives=[Primitive(attributes=Attributes(POSITION=0))]))
    shared_levels(b, 9, 0)
    b.save("vertices_beyond_bound.gltf", embed=True)


def node_cycle():
    """A node that is its own grandchild, under a root: a tree that never ends."""
    b = Builder()
    b.quad("loop", None)
    b.gltf.nodes = [Node(name="root", children=[1]), Node(name="a", mesh=0, children=[2]), Node(name="b", children=[1])]
    b.gltf.scenes = [Scene(nodes=[0])]
    b.gltf.scene = 0
    b.save("node_cycle.gltf", embed=True)


instanced()
textured()
glass()
draco()
instances_beyond_bound()
vertices_beyond_bound()
node_cycle()
