#pragma once
// What a download sends, file by file, and the preview set a live view
// starts from (proto/README.md, "Live first"): the reduced JPEG each frame's
// DNG embeds, served as a byte range of the stored file (the rig decodes
// nothing), beside a set.json made for the preview's size.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"
#include "veneerd/api.hpp"
#include "veneerd/store.hpp"

namespace veneerd {

// One file of a download: `size` bytes of `source` from `offset`, or, when
// `source` is empty, the bytes in `bytes`; sent from its byte `start` on (a
// resumed file, the bytes before it are the client's).
struct ServedFile {
  std::string rel;                // its relative path in the client's folder
  std::filesystem::path source;   // the stored file it is read from
  uint64_t offset = 0;
  uint64_t size = 0;
  std::string bytes;              // the content when made for the download (a preview's set.json)
  uint64_t start = 0;             // the first byte sent (resume_files)
};

// The files of stored set `id` as fetch_images sends them (set.json, the
// photos, the RAW files, ambient, mask, truth/ when asked), without those
// named in `skip` (a resumed pull); `skipped` gets the names left out.
veneer::Expected<std::vector<ServedFile>> set_files(const Store& store, const std::string& id, bool include_truth,
                                                     const std::vector<std::string>& skip,
                                                     std::vector<std::string>* skipped = nullptr);

// Resumes the files of `files` the client holds the start of: each whose
// `from` entry names at most its size and the CRC-32 of the rig's own first
// `offset` bytes is sent from there on (its `start`); any other is sent
// whole. Returns the entries honoured, in `files`' order. set.json is always
// sent whole (the client checks what it resumes against it).
std::vector<api::ResumeFrom> resume_files(std::vector<ServedFile>& files, const std::vector<api::ResumeFrom>& from);

// The preview set of stored set `id` (FetchPreviewRequest): set.json at the
// preview's size marked preview_of, and per frame the JPEG preview its DNG
// embeds; a set whose frames do not all embed one of the same size gets its
// developed photos at full size instead.
veneer::Expected<std::vector<ServedFile>> preview_files(const Store& store, const std::string& id);

}  // namespace veneerd
