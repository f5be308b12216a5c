#pragma once
// An image set: one object photographed once per lamp (DESIGN.md, "Image set").
//
// In memory:
//  - photos (images, ambient) are CV_32FC3, linear, OpenCV's BGR channel order,
//    scaled so that the full 16-bit range (65535) is 1.0; read with
//    ReadOptions::half_floats they are CV_16FC3 (all of a set's alike);
//  - normals are CV_32FC3 with channel 0 = x, 1 = y, 2 = z in the rig frame
//    (x right, y up, z toward the camera), (0,0,0) outside the object;
//  - masks are CV_8UC1, 255 = object, 0 = background;
//  - depth is CV_32FC1, metres along -z from the camera (0 = background);
//  - a light's intensity is [r, g, b] as in the manifest.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/raw.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::io {

enum class Role { unknown, destination, source };
const char* role_name(Role role);                 // "destination" | "source" | "unknown"
std::optional<Role> parse_role(const std::string&);

struct Light {
  int index = 0;                      // 0-based position in the set's light list
  std::string lamp_id;                // e.g. the Hue lamp id, or "sim-3"
  std::optional<cv::Vec3d> position_m;  // lamp position in the rig frame (near-light model)
  cv::Vec3d direction{0, 0, 1};       // unit vector from the object toward the lamp
  // [r, g, b] irradiance this lamp delivers at the rig origin (0,0,0), the
  // object's nominal position. A point p receives
  //   intensity * |position - 0|^2 / |position - p|^2   from direction (position - p)/|position - p|
  // (the near-light model); the distant-light model uses `intensity` and `direction` as they are.
  cv::Vec3f intensity{1, 1, 1};
};

struct CameraInfo {
  std::string model;
  double exposure_s = 0;
  double aperture = 0;
  int iso = 0;
  // Pinhole intrinsics in pixels when known (simulated sets, calibrated rigs):
  // focal length and principal point. 0 = unknown.
  double focal_px = 0;
  double cx = 0, cy = 0;
};

// Ground truth written by the simulator into <set>/truth/.
struct Truth {
  cv::Mat normals;  // CV_32FC3 x,y,z
  cv::Mat mask;     // CV_8UC1
  cv::Mat albedo;   // CV_32FC3 BGR
  cv::Mat depth;    // CV_32FC1
  bool present() const { return !normals.empty(); }
};

struct ImageSet {
  std::string id;
  Role role = Role::unknown;
  std::string object;
  std::string created;  // UTC, ISO 8601
  cv::Size size;        // [w, h]
  CameraInfo camera;
  std::vector<Light> lights;
  std::vector<cv::Mat> images;  // images[i] lit by lights[i]
  cv::Mat ambient;              // all lamps off; empty when absent
  cv::Mat mask;                 // supplied object mask (DiLiGenT mask.png); empty when absent
  std::vector<std::string> warnings;  // e.g. bright ambient frame
  std::string scene;            // simulator scene name, when simulated
  Truth truth;
  std::filesystem::path origin;  // folder it was read from (diagnostics)
  // What the photos were made from when read: "raw" (the camera's RAW files
  // through LibRaw), "raw-half" (the same at half size), "png" (16-bit
  // linear), "jpeg" (8-bit sRGB through the inverse sRGB curve), "pfm", "pnm";
  // empty for a set made in memory.
  std::string photos_from;
  // How the set was read, for people (`veneer info`): the layout
  // ("veneer-set/1", "DiLiGenT", "thesis", "RTI .lp"), and how its photos were
  // decoded (file kind, bit depth, linearisation or RAW decode). Empty for a
  // set made in memory; not written to set.json.
  std::string layout;
  std::string photos_read;
  // Photos read from RAW with RawOptions::camera_space are in the camera's
  // linear RGB (white-balanced, before its colour matrix: what photometric
  // stereo solves in); this matrix (on BGR pixels) makes them linear sRGB,
  // and to_colour_managed applies it. Identity for photos in sRGB.
  cv::Matx33f camera_to_srgb = cv::Matx33f::eye();
  // Camera RAW files to keep beside the photos (write_set writes raw[i] as
  // light_NN.<extension> and names it in set.json's images[i].raw; the
  // ambient's as ambient.<extension>). Empty = none. read_set does not fill
  // these (it decodes the files instead).
  struct RawFile {
    std::string extension;  // e.g. "dng", "cr2" (no dot)
    std::string bytes;
  };
  std::vector<RawFile> raw;
  RawFile ambient_raw;
  // The camera's developed photos (its JPEGs, as a RAW+JPEG body delivers
  // them) to store instead of encoding images[i] as a 16-bit PNG: write_set
  // writes developed[i] as light_NN.<extension> and names it in
  // images[i].file (the ambient's as ambient.<extension>). Empty = PNG.
  std::vector<RawFile> developed;
  RawFile ambient_developed;
  // A preview set (a reduced copy a live view starts from while the full
  // files are still coming, proto/README.md "Live first"): the set it is a
  // preview of and that set's size. set.json "preview_of": {"id", "size"}.
  struct PreviewOf {
    std::string id;
    cv::Size size;
  };
  std::optional<PreviewOf> preview_of;
};

// Makes a set read in the camera's space (ImageSet::camera_to_srgb) linear
// sRGB: its photos and ambient frame in place (frames in parallel), and the
// matrix the identity. Nothing for a set already in sRGB.
void to_colour_managed(ImageSet& set);

// veneer:   set.json + light_NN.png (+ ambient.png, mask.png, truth/)
// diligent: filenames.txt, light_directions.txt, optional light_intensities.txt and mask.png
// thesis:   lights.txt ("x y z [r g b]" per lamp) + images <N>.<ext> taken in increasing N,
//           optional ambient.*, mask.pgm|.png, normals.pfm (kept as truth)
// rti:      the RTI community's capture folder (RTIBuilder, Relight): one *.lp light file
//           (in the folder or its assembly-files/) naming each photo and its light direction
//
// The DiLiGenT, thesis and RTI photos may be PNG, PPM/PGM, PFM, JPEG, TIFF or camera
// RAW files (DNG, CR2, NEF, ARW, ... by their names, through LibRaw with
// ReadOptions::raw). JPEGs are sRGB and always linearised; 8-bit PNG and TIFF
// photos are linearised in RTI folders (developed photos) and taken as linear in
// the DiLiGenT and thesis layouts (whose 8-bit files are linear by convention);
// 16-bit and float files are linear.
enum class SetFormat { automatic, veneer, diligent, thesis, rti };
const char* format_name(SetFormat);  // "veneer-set/1" | "DiLiGenT" | "thesis" | "RTI .lp" | "automatic"

// Which files a veneer set's photos come from when it has both.
enum class PhotoSource {
  automatic,  // the RAW files when every photo (and the ambient frame, if any) has one, else the developed ones
  raw,        // the RAW files; an error when one is missing
  developed,  // the PNG/JPEG files named by images[].file, ignoring RAW files
};
const char* photo_source_name(PhotoSource);  // "auto" | "raw" | "developed"
Expected<PhotoSource> parse_photo_source(const std::string&);

struct ReadOptions {
  SetFormat format = SetFormat::automatic;  // automatic: set.json -> veneer, filenames.txt -> DiLiGenT,
                                            // lights.txt -> thesis, one *.lp -> RTI
  bool load_truth = true;                   // read <set>/truth/ when present
  bool load_truth_appearance = true;        // with load_truth: also truth/albedo.png and depth.pfm (a
                                            // transfer measures with normals and mask only; at 5600x3750
                                            // they are 340 MB to decode per set)
  PhotoSource photos = PhotoSource::automatic;  // veneer sets: RAW or developed photos (default: RAW where present)
  RawOptions raw;                           // how RAW files are decoded (half size, demosaic), in every layout
  bool load_photos = true;                  // veneer sets: false reads the manifest, mask and truth only
                                            // (images left empty; for results taken from a cache)
  bool half_floats = false;                 // the photos and the ambient frame as CV_16FC3 (half floats,
                                            // the precision the result cache stores photos at), each made
                                            // so as it is decoded: a set's frames are never all float at
                                            // once (issue 42: peak memory). Default off: CV_32FC3
  Status check() const;
};

// Reads a set folder. Every failure names the file and the problem. The
// photos are decoded in parallel, each file once; `progress` hears
// ("reading <set>", fraction of files decoded) and a cancel stops between files.
// Photos decoded from RAW files define the set's size: when it differs from
// set.json's (the rig's developed photos are often smaller), the camera
// intrinsics are scaled and the mask and truth resized to match.
Expected<ImageSet> read_set(const std::filesystem::path& folder, const ReadOptions& options = {},
                            const Progress& progress = {});

// Writes a veneer-set/1 folder atomically: everything goes to a temporary
// sibling folder that is fsynced and renamed into place, so a reader never sees
// half a set. Fails (and leaves nothing) if `folder` exists unless overwrite.
Status write_set(const ImageSet& set, const std::filesystem::path& folder, bool overwrite = false);

// Checks the in-memory invariants (sizes, counts, unit directions, types).
Status validate(const ImageSet& set);

// --- the manifest on its own (used by read_set, `veneer info`, the fuzz target) ---

inline constexpr const char* kSetFormat = "veneer-set/1";
// How far a light direction's length may be from 1 before it is refused.
inline constexpr double kUnitTolerance = 1e-3;

// A parsed set.json: the set without pixels, and the files it names (relative
// to the set folder, already checked to stay inside it).
struct Manifest {
  ImageSet set;                             // lights sorted by index, no images loaded
  std::vector<std::filesystem::path> image_files;  // image_files[i] is lit by set.lights[i]
  std::vector<std::filesystem::path> raw_files;    // the camera RAW file of image i (images[i].raw); empty when none
  std::filesystem::path ambient_file;       // empty when absent
  std::filesystem::path ambient_raw_file;   // the ambient frame's RAW file ("ambient_raw"); empty when none
  std::filesystem::path mask_file;          // empty when absent
};

// Parses and checks set.json text without touching the disk; `folder` only
// names the file in errors.
Expected<Manifest> parse_manifest(const std::string& json, const std::filesystem::path& folder);

// The set.json write_set would write for `set` (images named light_NN.png).
std::string manifest_json(const ImageSet& set);

}  // namespace veneer::io
