# The isobar Rust core as an imported static library, built by cargo.
#
# Corrosion is not available on Debian 12, so cargo is driven by a custom target that
# runs on every build (cargo itself decides whether anything changed, in well under a
# second when nothing did). The static library is a BYPRODUCT, so Ninja re-links the
# module only when cargo actually rewrote it.
#
# Result: the GLOBAL imported target `isobar::core` (include dir = rust-core/include).

set(ISOBAR_REPO_ROOT "${CMAKE_CURRENT_LIST_DIR}/../.." CACHE PATH
  "Root of the isobar cargo workspace")
get_filename_component(ISOBAR_REPO_ROOT "${ISOBAR_REPO_ROOT}" ABSOLUTE)

find_program(ISOBAR_CARGO cargo
  HINTS "$ENV{CARGO_HOME}/bin" "$ENV{HOME}/.cargo/bin"
  DOC "cargo, to build the isobar core")
if (NOT ISOBAR_CARGO)
  message(FATAL_ERROR "cargo not found: the isobar core needs a Rust toolchain (rustup)")
endif ()

# The workspace's own target directory: both build trees (VTK and ParaView) and the
# other hosts share one compilation of the core.
set(ISOBAR_CARGO_TARGET_DIR "${ISOBAR_REPO_ROOT}/target" CACHE PATH
  "cargo --target-dir for the isobar core")
set(ISOBAR_CORE_LIBRARY "${ISOBAR_CARGO_TARGET_DIR}/release/libisobar.a")

add_custom_target(isobar_cargo ALL
  COMMAND "${ISOBAR_CARGO}" build --release --quiet -p isobar --lib
          --manifest-path "${ISOBAR_REPO_ROOT}/Cargo.toml"
          --target-dir "${ISOBAR_CARGO_TARGET_DIR}"
  BYPRODUCTS "${ISOBAR_CORE_LIBRARY}"
  WORKING_DIRECTORY "${ISOBAR_REPO_ROOT}"
  COMMENT "cargo build --release -p isobar (static core)"
  USES_TERMINAL
  VERBATIM)

find_package(Threads REQUIRED)

add_library(isobar::core STATIC IMPORTED GLOBAL)
set_target_properties(isobar::core PROPERTIES
  IMPORTED_LOCATION "${ISOBAR_CORE_LIBRARY}"
  INTERFACE_INCLUDE_DIRECTORIES "${ISOBAR_REPO_ROOT}/rust-core/include"
  # What the Rust standard library needs on Linux (`--print native-static-libs`).
  INTERFACE_LINK_LIBRARIES "Threads::Threads;${CMAKE_DL_LIBS};m")
add_dependencies(isobar::core isobar_cargo)
