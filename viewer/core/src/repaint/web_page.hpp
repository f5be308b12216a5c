#pragma once
// The web page's own files (web_export.hpp): index.html, the viewer.
#include <string>

namespace veneer::repaint::web {

// index.html: the page that shows `object` in `material`'s material from
// look.js (the fit and its planes), still.jpg without WebGL or canvas. The
// names are escaped here.
std::string index_html(const std::string& object, const std::string& material, int width, int height);

// `text` with &, <, >, " and ' as HTML entities.
std::string html_escape(const std::string& text);

// RFC 4648 base64 of `bytes`.
std::string base64(const std::string& bytes);

}  // namespace veneer::repaint::web
