# Sourced by setup.sh and check_install_space.sh after they set $repository:
# compile through ccache when it is installed (setup.sh test installs it).
# Both workspaces live inside the repository, so with the repository as
# CCACHE_BASEDIR their compile commands differ in no path, and the install
# check's build takes the test build's objects instead of compiling the
# package a second time.
# The cache lives in the ignored .ccache/ of the repository (the build writes
# there anyway), not in the user's home.
compiler_cache_options=()
export CCACHE_BASEDIR=$repository
export CCACHE_DIR=${CCACHE_DIR:-$repository/.ccache}
if command -v ccache >/dev/null; then
  compiler_cache_options=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
