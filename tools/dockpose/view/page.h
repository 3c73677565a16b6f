/* SPDX-License-Identifier: MIT */
/*
 * The operator's page (page.html), built into the binary: CMake writes
 * page.cpp from page.cpp.in with page.html's text in a raw string, so the
 * page is plain HTML/CSS/JS with no build step and nothing to fetch.
 */
#pragma once

namespace dockpose::tool {

extern const char *const kViewPage;

} /* namespace dockpose::tool */
