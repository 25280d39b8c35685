#!/usr/bin/env bash
# Installs Intel Open Image Denoise 2.5.1 (its CPU device) into .oidn/lib of this checkout, where
# .cargo/config.toml points the `oidn` crate (OIDN_DIR) and coordinator/build.rs the binary's
# run path. Debian has no package; the PyPI wheel `pyoidn` ships the official Linux libraries.
# Only the four files the CPU device needs are kept (54 MB of the wheel's 169 MB: the wheel holds
# copies where a release has symlinks, and the CUDA, HIP and SYCL devices).
set -euo pipefail
cd "$(dirname "$0")/.."
dest=.oidn/lib
version=2.5.1
if [ -e "$dest/libOpenImageDenoise.so" ] && [ -e "$dest/libOpenImageDenoise_core.so.$version" ] &&
    [ -e .oidn/NOTICE.txt ]; then
    exit 0
fi
if ! python3 -m pip --version >/dev/null 2>&1; then
    # pip (and Python, if missing) from Debian; needs root, as the README says.
    apt-get update && apt-get install -y python3 python3-pip
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "== Open Image Denoise $version from PyPI (pyoidn)"
python3 -m pip download --quiet --no-deps --only-binary=:all: "pyoidn==$version.0" -d "$tmp"
python3 -m zipfile -e "$tmp"/pyoidn-*.whl "$tmp/wheel"
src="$tmp/wheel/pyoidn/oidn/lib"
# Staged, then moved into place: a running coordinator keeps the files it has mapped.
staged="$tmp/lib"
mkdir -p "$staged"
for f in "libOpenImageDenoise.so.$version" "libOpenImageDenoise_core.so.$version" \
    "libOpenImageDenoise_device_cpu.so.$version" libtbb.so.12; do
    cp "$src/$f" "$staged/"
done
# The libraries find each other through $ORIGIN/../lib: the folder must be called lib.
ln -sf "libOpenImageDenoise.so.$version" "$staged/libOpenImageDenoise.so.2"
ln -sf libOpenImageDenoise.so.2 "$staged/libOpenImageDenoise.so"
mkdir -p .oidn
rm -rf .oidn/lib.old
if [ -e "$dest" ]; then mv "$dest" .oidn/lib.old; fi
mv "$staged" "$dest"
rm -rf .oidn/lib.old
# Both are Apache-2.0 and the wheel carries no license text: Debian's copy of the license
# (base-files) and a notice go beside the libraries, and into the Docker image with them.
cp /usr/share/common-licenses/Apache-2.0 .oidn/LICENSE-Apache-2.0.txt
cat >.oidn/NOTICE.txt <<NOTICE
lib/ holds Intel Open Image Denoise $version (libOpenImageDenoise*, https://www.openimagedenoise.org)
and Intel oneAPI Threading Building Blocks (libtbb), both under the Apache License 2.0
(LICENSE-Apache-2.0.txt), as built by Intel and shipped in the PyPI wheel pyoidn==$version.0.
NOTICE
echo "installed in $dest"
