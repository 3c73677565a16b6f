# SPDX-License-Identifier: MIT
#
# Install rules and the Debian package (CPack DEB) of the dockpose sensor.
# Included at the end of the top-level CMakeLists.txt, after every target exists.
#
#   cmake --build build/aarch64 --target package   ->  build/aarch64/dockpose_<version>_arm64.deb
#   DESTDIR=/tmp/root cmake --install build/host --prefix /usr   (a staged install, for a look)
#
# What goes where (relative destinations are below the install prefix, /usr in the package;
# /etc and /lib/systemd are absolute: Debian has them there whatever the prefix):
#
#   /usr/bin/dockposed                        the daemon
#   /usr/bin/dockpose                         the host tool (tools/CMakeLists.txt installs it)
#   /usr/bin/dockpose-candecode               wrapper: candecode with the installed DBC
#   /usr/share/dockpose/candecode             scripts/candecode, unchanged
#   /usr/share/dockpose/dockpose.dbc          the CAN contract
#   /usr/include/dockpose/dockpose_can.h      the controller's header-only encoder/decoder
#   /usr/include/dockpose/dockpose_can_cmac.h its MAC with OpenSSL (authenticated frames)
#   /etc/dockpose/boards/<name>/              board.json, camera.json, target.json, README.md (conffiles)
#   /etc/default/dockposed                    which board the service runs (conffile)
#   /lib/systemd/system/dockposed.service     the service
#   /lib/udev/rules.d/60-dockpose.rules       gpiochip and dma_heap device groups
#   /usr/share/doc/dockpose/                  README.md and docs/
include(GNUInstallDirs)

set(DOCKPOSE_PACKAGING_DIR ${CMAKE_CURRENT_LIST_DIR})
set(DOCKPOSE_SYSTEMD_UNIT_DIR /lib/systemd/system CACHE PATH "Where the systemd unit is installed (absolute)")
set(DOCKPOSE_UDEV_RULES_DIR /lib/udev/rules.d CACHE PATH "Where the udev rules are installed (absolute)")
set(DOCKPOSE_CONF_DIR /etc/dockpose CACHE PATH "Where the board folders are installed (absolute)")
set(DOCKPOSE_DATA_DIR ${CMAKE_INSTALL_DATADIR}/dockpose)

# ---- programs -----------------------------------------------------------------------------
if(TARGET dockposed)
	install(TARGETS dockposed RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()
# The host tool `dockpose` is installed by tools/CMakeLists.txt (RUNTIME DESTINATION bin, the same
# place); a second rule here would only install it twice.

# The independent python decoder. scripts/candecode finds the DBC next to itself in the source
# tree (../firmware/protocol/); installed, the wrapper hands it the installed copy with --dbc.
install(PROGRAMS ${PROJECT_SOURCE_DIR}/scripts/candecode DESTINATION ${DOCKPOSE_DATA_DIR})
install(PROGRAMS ${DOCKPOSE_PACKAGING_DIR}/dockpose-candecode DESTINATION ${CMAKE_INSTALL_BINDIR})

# ---- the CAN contract ---------------------------------------------------------------------
install(FILES ${PROJECT_SOURCE_DIR}/firmware/protocol/dockpose.dbc DESTINATION ${DOCKPOSE_DATA_DIR})
install(FILES ${PROJECT_SOURCE_DIR}/firmware/protocol/dockpose_can.h
	${PROJECT_SOURCE_DIR}/firmware/protocol/dockpose_can_cmac.h
	DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/dockpose)

# ---- boards -------------------------------------------------------------------------------
# Only the boards compiled into dockposed (DOCKPOSE_BOARDS, board/CMakeLists.txt): a board folder
# the daemon cannot run would be a trap. Their data files (*.json, README.md) go to
# /etc/dockpose/boards/<name>/; wiring.cpp and backends.cmake are build inputs and stay behind.
# Every file under /etc is a conffile (listed below), so dpkg keeps an integrator's edits on upgrade.
set(dockpose_conffiles "")
foreach(board IN LISTS DOCKPOSE_BOARDS)
	set(board_dir ${PROJECT_SOURCE_DIR}/board/${board})
	if(NOT EXISTS ${board_dir}/board.json)
		message(FATAL_ERROR "DOCKPOSE_BOARDS names '${board}', but board/${board}/board.json does not exist")
	endif()
	# CONFIGURE_DEPENDS: a data file added to the folder re-runs configure, so the install rules
	# and the conffiles list never disagree.
	file(GLOB board_files CONFIGURE_DEPENDS LIST_DIRECTORIES false
		${board_dir}/*.json ${board_dir}/README.md)
	list(SORT board_files)
	install(FILES ${board_files} DESTINATION ${DOCKPOSE_CONF_DIR}/boards/${board})
	foreach(f IN LISTS board_files)
		get_filename_component(name ${f} NAME)
		string(APPEND dockpose_conffiles "${DOCKPOSE_CONF_DIR}/boards/${board}/${name}\n")
	endforeach()
endforeach()

# ---- systemd, udev, the service's settings ------------------------------------------------
install(FILES ${DOCKPOSE_PACKAGING_DIR}/dockposed.service DESTINATION ${DOCKPOSE_SYSTEMD_UNIT_DIR})
install(FILES ${DOCKPOSE_PACKAGING_DIR}/60-dockpose.rules DESTINATION ${DOCKPOSE_UDEV_RULES_DIR})
install(FILES ${DOCKPOSE_PACKAGING_DIR}/dockposed.default DESTINATION /etc/default RENAME dockposed)
string(APPEND dockpose_conffiles "/etc/default/dockposed\n")

# ---- documentation ------------------------------------------------------------------------
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}
	FILES_MATCHING PATTERN "*.md" PATTERN "*.png" PATTERN "*.svg")
foreach(license LICENSE LICENSE.md COPYING)
	if(EXISTS ${PROJECT_SOURCE_DIR}/${license})
		install(FILES ${PROJECT_SOURCE_DIR}/${license} DESTINATION ${CMAKE_INSTALL_DOCDIR} RENAME copyright)
		break()
	endif()
endforeach()

# ---- the Debian package -------------------------------------------------------------------
# Debian's architecture name for the target (not the build machine: CPack would ask dpkg).
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64|ARM64)$")
	set(dockpose_deb_arch arm64)
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|amd64|AMD64)$")
	set(dockpose_deb_arch amd64)
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^armv7")
	set(dockpose_deb_arch armhf)
else()
	message(WARNING "packaging: no Debian architecture known for CMAKE_SYSTEM_PROCESSOR "
		"'${CMAKE_SYSTEM_PROCESSOR}'; set CPACK_DEBIAN_PACKAGE_ARCHITECTURE")
	set(dockpose_deb_arch ${CMAKE_SYSTEM_PROCESSOR})
endif()

# Runtime library packages, named after the libraries this build links (Debian 12: libcamera 0.0.3
# is libcamera0.0.3, libgpiod 1.6 is libgpiod2; a board OS with another libcamera, such as
# Raspberry Pi OS's, has another package name and needs a build against its own -dev package).
# The package is for a board's hardware: without the real backends (a sim-only DOCKPOSE_BOARDS)
# there is none to build.
if(NOT TARGET dockpose_hal_libcamera OR NOT TARGET dockpose_hal_gpiod)
	message(STATUS "packaging: no Debian package (the boards built here wire no libcamera and libgpiod)")
	return()
endif()
find_package(PkgConfig REQUIRED)
pkg_check_modules(DOCKPOSE_DEB_LIBCAMERA QUIET libcamera)
pkg_check_modules(DOCKPOSE_DEB_LIBGPIOD QUIET libgpiod)
if(NOT DOCKPOSE_DEB_LIBCAMERA_FOUND OR NOT DOCKPOSE_DEB_LIBGPIOD_FOUND)
	message(FATAL_ERROR "packaging: pkg-config finds no libcamera or libgpiod for this target "
		"(run scripts/setup)")
endif()
set(libcamera_version ${DOCKPOSE_DEB_LIBCAMERA_VERSION})
# The package that holds libcamera is named after the soname of the library this build links
# (Debian's policy: libcamera.so.0.0.3 is in libcamera0.0.3, Raspberry Pi OS's libcamera.so.0.7 in
# libcamera0.7), read from the library file pkg-config names (readelf -d: its SONAME).
set(libcamera_file "")
foreach(lib IN LISTS DOCKPOSE_DEB_LIBCAMERA_LINK_LIBRARIES)
	if(lib MATCHES "/libcamera\\.so$")
		set(libcamera_file ${lib})
	endif()
endforeach()
find_program(DOCKPOSE_READELF NAMES readelf ${CMAKE_READELF})
if(NOT libcamera_file OR NOT DOCKPOSE_READELF)
	message(FATAL_ERROR "packaging: no libcamera.so among '${DOCKPOSE_DEB_LIBCAMERA_LINK_LIBRARIES}', "
		"or no readelf: cannot name libcamera's package")
endif()
execute_process(COMMAND ${DOCKPOSE_READELF} -d ${libcamera_file} OUTPUT_VARIABLE libcamera_dynamic
	RESULT_VARIABLE readelf_rc)
string(REGEX MATCH "\\(SONAME\\)[^[]*\\[libcamera\\.so\\.([0-9.]+)\\]" libcamera_soname_line
	"${libcamera_dynamic}")
if(NOT readelf_rc EQUAL 0 OR NOT CMAKE_MATCH_1)
	message(FATAL_ERROR "packaging: no SONAME libcamera.so.N in ${libcamera_file} (readelf -d)")
endif()
set(libcamera_abi ${CMAKE_MATCH_1})
message(STATUS "packaging: ${libcamera_file} has SONAME libcamera.so.${libcamera_abi}: "
	"Depends libcamera${libcamera_abi}")
string(REGEX MATCH "^[0-9]+\\.[0-9]+\\.[0-9]+" libcamera_min "${libcamera_version}")
string(REGEX MATCH "^[0-9]+" libgpiod_major "${DOCKPOSE_DEB_LIBGPIOD_VERSION}")
math(EXPR libgpiod_soname "${libgpiod_major} + 1")	# libgpiod 1.x: libgpiod.so.2, 2.x: libgpiod.so.3
string(REGEX MATCH "^[0-9]+\\.[0-9]+" libgpiod_min "${DOCKPOSE_DEB_LIBGPIOD_VERSION}")

# Lower bounds: libc6, libstdc++6 and libgcc-s1 as dpkg-shlibdeps reports them for dockposed built
# with GCC 12 on Debian 12 (glibc symbol versions up to 2.35); libsystemd0 209 is where sd_notify's
# symbol version starts; libssl3 3.0 is where EVP_MAC (the CAN authentication's CMAC) starts;
# libcamera and libgpiod: the versions built against.
# libcamera-ipa holds the image processing modules; libcamera0.0.3 only suggests it, but no camera
# pipeline with an ISP (the Raspberry Pi's) starts without it. adduser: postinst creates the user.
set(dockpose_deb_depends
	"libc6 (>= 2.35)"
	"libstdc++6 (>= 12)"
	"libgcc-s1 (>= 3.4)"
	"libsystemd0 (>= 209)"
	"libssl3 (>= 3.0.0)"
	"libcamera${libcamera_abi} (>= ${libcamera_min})"
	"libcamera-ipa (>= ${libcamera_min})"
	"libgpiod${libgpiod_soname} (>= ${libgpiod_min})"
	"adduser")
list(JOIN dockpose_deb_depends ", " dockpose_deb_depends)
set(DOCKPOSE_DEB_DEPENDS "" CACHE STRING
	"Depends of the Debian package; empty: derived from the libraries this build links")
set(DOCKPOSE_DEB_MAINTAINER "Seed a641eb8c maintainers <maintainers@users.noreply.h-seed-a641eb8c.example>"
	CACHE STRING "Maintainer field of the Debian package")
mark_as_advanced(DOCKPOSE_DEB_DEPENDS DOCKPOSE_DEB_MAINTAINER)
if(DOCKPOSE_DEB_DEPENDS)
	set(dockpose_deb_depends "${DOCKPOSE_DEB_DEPENDS}")
endif()

# The maintainer scripts and the conffiles list (generated: it names every board file).
set(dockpose_control_dir ${PROJECT_BINARY_DIR}/packaging/control)
file(MAKE_DIRECTORY ${dockpose_control_dir})
file(CONFIGURE OUTPUT ${dockpose_control_dir}/conffiles CONTENT "${dockpose_conffiles}")
foreach(script postinst prerm postrm)
	# Copied so the package's mode does not depend on the checkout's (dpkg wants 0755).
	file(COPY ${DOCKPOSE_PACKAGING_DIR}/${script} DESTINATION ${dockpose_control_dir}
		FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE
			WORLD_READ WORLD_EXECUTE)
endforeach()
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS
	${DOCKPOSE_PACKAGING_DIR}/postinst ${DOCKPOSE_PACKAGING_DIR}/prerm ${DOCKPOSE_PACKAGING_DIR}/postrm)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME dockpose)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "dockpose")
set(CPACK_PACKAGE_CONTACT "${DOCKPOSE_DEB_MAINTAINER}")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_PACKAGE_DESCRIPTION
	"Firmware of a smart camera that finds a docking target marked with infrared LEDs and reports
its 6-DoF pose (translation, rotation, covariance) on CAN, so that a robot arm can dock with it.
Contains the daemon dockposed with its systemd service, the board configurations, the CAN
database (DBC), the controller's C++ header and the dockpose-candecode CAN decoder.")
set(CPACK_DEBIAN_PACKAGE_NAME dockpose)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)	# dockpose_<version>_<arch>.deb
set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE ${dockpose_deb_arch})
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "${dockpose_deb_depends}")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "python3, python3-can, python3-canmatrix, can-utils")
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS OFF)	# Depends are written above, for the target's Debian
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
	${dockpose_control_dir}/conffiles
	${dockpose_control_dir}/postinst
	${dockpose_control_dir}/prerm
	${dockpose_control_dir}/postrm)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION TRUE)
set(CPACK_STRIP_FILES TRUE)
set(CPACK_SOURCE_GENERATOR "")
include(CPack)
