"""What tests/ and benchmarks/ both use, so that neither imports the other: mesh builders
and the hard cases' checks (hardcheck), the loaders' fuzz inputs (fuzz_inputs), the memory
a load takes (loadmemory), hand-written mesh files (meshfiles, gltfwrite). It imports
neither (tests/test_folders.py checks)."""
