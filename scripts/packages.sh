# The Debian packages every Tessera build needs, in one list that scripts/build.sh, ci_sanitize.sh and
# ci_fuzz.sh source (each adds its own extras). A new dependency goes here once.
TESSERA_PACKAGES=(g++ cmake make pkg-config libtbb-dev libopenexr-dev libpng-dev zlib1g-dev libcli11-dev
                  libfmt-dev nlohmann-json3-dev libopenimageio-dev libosd-dev)
