#pragma once
// veneer-viewer's window: connect to a rig, capture, browse and pull sets,
// compute a transfer in the background, look at every picture, watch the live
// view repainted onto the destination, relight, export. Every computation is a
// call into viewer/core, run off the GUI thread; this file only wires widgets.
#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <optional>

#include <QElapsedTimer>
#include <QFutureWatcher>
#include <QMainWindow>
#include <QSettings>
#include <QThreadPool>
#include <QTimer>

#include "image_view.hpp"
#include "library.hpp"
#include "rig_link.hpp"
#include "sphere_pad.hpp"
#include "step_clock.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/repaint/live_session.hpp"
#include "veneer/repaint/relight.hpp"

class QCheckBox;
class QComboBox;
class QDialog;
class QMenu;
class QDoubleSpinBox;
class QHBoxLayout;
class QLabel;
class QLineEdit;
class QProgressBar;
class QPushButton;
class QSpinBox;
class QTabWidget;
class QTreeWidget;
class QTreeWidgetItem;

namespace veneer::app {

// One object the window has loaded: the set and what photometric stereo says of it.
struct LoadedSet {
  QString folder;
  veneer::io::ImageSet set;
  std::optional<veneer::ps::PsResult> normals;  // filled in the background after loading
  cv::Mat median;                               // per-pixel median photo (linear BGR)
  cv::Mat median_picture;                       // the same, tonemapped (8-bit), for the views
  QImage median_image;                          // ... as the views show it (made by the loader)
  cv::Mat histogram;                            // ... its 64-bin luminance histogram (CV_32F)
  cv::Mat hand_mask;  // segmentation by hand (CV_8UC1, 255 = object); empty = automatic
  int hand_version = 0;
  bool live_size = false;  // read at the live view's width (reduced decode), smaller than the set
};

class MainWindow : public QMainWindow {
  Q_OBJECT
 public:
  struct Options {
    QString rig;         // host:port to connect to at start (empty = none)
    QString token_file;  // the rig's token file
    QString destination, source;  // local sets to load at start
    QString workdir;     // where pulled sets go (default: the app's data folder)
  };
  explicit MainWindow(const Options& options, QWidget* parent = nullptr);
  ~MainWindow() override;

  // What the tests and scripts drive (the buttons call the same).
  RigLink& rig() { return rig_; }
  void connectToRig(const QString& endpoint, const QString& token_file);
  bool loadLocalSet(const QString& folder, veneer::io::Role as);
  void startTransfer();
  void cancelTransfer();
  bool computing() const { return computing_; }
  const veneer::pipeline::TransferResult* result() const { return result_.get(); }
  const LoadedSet* destination() const { return dst_.get(); }
  const LoadedSet* source() const { return src_.get(); }
  QString lastMessage() const { return last_message_; }
  cv::Mat lastLiveFrame() const { return live_frame_; }
  cv::Mat lastRepaintedFrame() const { return live_repainted_; }
  int liveFramesShown() const { return live_frames_; }
  // Transfers that reused the prepared objects (normals, masks) and
  // recomputed only the map: what a change of a matching option triggers.
  int mapOnlyRuns() const { return map_only_runs_; }
  int repaintOnlyRuns() const { return repaint_only_runs_; }
  double liveFps() const { return live_fps_; }
  QString workdir() const { return workdir_; }
  // Grabs every view as <dir>/<tab>.png; returns the files written.
  QStringList saveScreenshots(const QString& dir);
  void showTab(const QString& name);
  // Saves the tab shown, as on screen, as a PNG; returns the file ("" and a
  // message when it cannot).
  QString snapshotTo(const QString& file);
  // The Look tab's "Show" choice by its text (e.g. "specular enhancement").
  bool showLook(const QString& what);
  QString exposureText() const { return exposure_text_; }
  // Segmentation by hand (segmentation.cpp), what the views' shift+drag
  // (rectangle) and ctrl/alt+drag (brush in/out) do: the object mask the
  // transfer then uses for that set, shown as an outline.
  void setHandRect(veneer::io::Role set, const QRect& rect);
  void brushHandMask(veneer::io::Role set, QPoint pixel, bool add, int radius = 0);
  void clearHandMask(veneer::io::Role set);
  // Writes the hand masks as <dir>/dst-mask.png and src-mask.png, what
  // `veneer transfer --dst-mask/--src-mask` reads; returns the files written.
  QStringList exportMasksTo(const QString& dir);

  // The one flow (flow.cpp): with it on (the default), every capture stored
  // on the rig -- from its button, the Capture panel or the Live tab -- is
  // pulled and loaded as its role, the map is computed with the current
  // settings as soon as both sets exist, and the live repaint starts.
  bool autoFlow() const;
  void setAutoFlow(bool on);
  // Exports without a dialog (the menu's entries ask for the place, then
  // call these); each runs off the GUI thread with progress and cancel.
  void exportMapTo(const QString& dir);
  void exportResultsTo(const QString& dir);
  void exportRelightVideoTo(const QString& file);
  bool exporting() const { return job_running_; }
  // Cancels whatever the status line shows running (compute, capture, pull,
  // load, export).
  void cancelStep();
  // The one line of status: the step running, its progress and time left.
  QString stepLine() const;
  // Loads a set off the GUI thread (read, median, thumbnail), then shows it.
  // Without a role the set is only listed (a pull in manual mode); with
  // Role::unknown it is used as the role its manifest gives.
  void loadSetInBackground(const QString& folder, std::optional<veneer::io::Role> as);
  int loadsRunning() const { return loads_running_; }
  // Shows a map kept in the library again (the Sets panel's "Open map" and a
  // double click on a map row): loads its destination and source in their
  // roles, with the options and hand masks it was computed with, and repaints
  // through the stored map -- no matching. False, with a message naming what
  // is missing, when its map file or one of its sets is gone; a set found
  // replaced (another id in its folder) is said once both are loaded.
  bool openLibraryMap(const QString& map_folder);
  // Lamp calibration (calibration.cpp): finds the sphere and each lamp's
  // highlight in a chrome-sphere set, writes the lights file (what `veneer
  // normals --lights` reads) and shows the circle and highlights found.
  bool calibrateLamps(const QString& sphere_folder, const QString& lights_file);
  QImage calibrationImage() const { return calibration_image_; }

  // Live first (live_first.cpp): the automatic flow loads the pulled sets at
  // the live view's width through reduced decodes (io/reduced.hpp), goes live
  // on that map, then makes the full-resolution map in the background (the
  // pipeline's, as `veneer transfer` makes it) with progress and time left in
  // the status bar, and swaps it in when done. 0 = off: full resolution first.
  void setLiveWidth(int px) { live_width_ = px; }
  int liveWidth() const { return live_width_; }
  bool fullResolutionRunning() const { return full_running_; }
  int fullResolutionSwaps() const { return full_swaps_; }  // full-resolution maps swapped in
  QString fullResolutionLine() const;

 private:
  void addCalibrationMenu(QMenu* menu);
  void buildUi();
  QWidget* buildConnectPanel();
  QWidget* buildCapturePanel();
  QWidget* buildSetsPanel();
  QWidget* buildTransferPanel();
  QWidget* buildLookTab();
  QWidget* buildLiveTab();
  QWidget* buildRelightTab();
  void buildMenus();

  void message(const QString& text, bool error = false);
  void updateStatusLine();
  void onRigEvent(const veneer::rig::Event& e);
  void onSetsListed(const std::vector<veneer::rig::SetSummary>& sets);
  void onLiveFrame(const veneer::rig::LiveFrame& frame);
  // What the live view's thread makes of one frame, for the GUI to show.
  struct LiveOut {
    uint64_t seq = 0;
    cv::Mat frame, repainted;  // empty frame: not a JPEG
    QImage shown_image, repainted_image;
    QString state, refusal;
  };
  void showLiveFrame(const LiveOut& out, const veneer::repaint::LiveSession* session);
  void onTransferDone();
  void matchOptionChanged();
  // transfer_panel.cpp: the presets of the Transfer panel
  struct Preset {
    QString name, method, feature;
    int patch, candidates;
    double threshold;
    int iterations;
    double coherent_threshold, coherent_smooth, coherent_guide, uniformity;
    int blend;
    double blend_guide;
    bool fast;
  };
  static const std::vector<Preset>& presets();
  void applyPreset(const Preset& preset);
  void updateRelightLabel(const cv::Vec3d& direction);
  QString preparationKey() const;
  void refreshLook();
  void refreshLookNow();
  void updateLampBoxes();
  void updateHistogram();
  std::shared_ptr<LoadedSet> setFor(veneer::io::Role role) const { return role == veneer::io::Role::source ? src_ : dst_; }
  bool startHandMask(LoadedSet& s);
  void handMaskChanged(veneer::io::Role role);
  void showOrigin(QPoint destination_pixel);
  void refreshRelight();
  void setLoaded(std::shared_ptr<LoadedSet> loaded, veneer::io::Role as);
  void computeNormals(std::shared_ptr<LoadedSet> loaded);
  void addLocalItem(const QString& folder, const veneer::io::ImageSet& set, const cv::Mat& thumbnail = {});
  // sets_panel.cpp
  QTreeWidgetItem* localItem(const QString& folder, bool create);
  void showLibrary();
  void addMapItem(const LibraryMap& map);
  void saveMapToLibrary();
  // A set finished loading as `role`: true while a library map being reopened
  // waits for its sets (and when it then starts), so the flow does not compute.
  bool reopenWhenLoaded(const QString& folder, veneer::io::Role role);
  void askDelete(QTreeWidgetItem* item);
  void onTrashListed(const std::vector<veneer::rig::SetSummary>& sets);
  void restoreFromTrash(const QString& id);
  QTreeWidgetItem* selectedItem() const;
  void pullSelected();
  void useSelected(veneer::io::Role as);
  void exportMap();
  void exportResults();
  void exportRelightVideo();
  void rememberRig(const QString& endpoint);

  // flow.cpp
  void flowSetStored(const QString& id, veneer::io::Role role);
  void flowPulled(const QString& id, const QString& folder);
  void flowMaybeCompute();
  void flowMaybeGoLive();
  void showStep();
  // export.cpp: runs `job` off the GUI thread as a step of the status line.
  void runJob(const QString& kind, const QString& text,
              std::function<veneer::Status(const veneer::Progress&)> job, const QString& done);

  RigLink rig_;
  ViewSync sync_;
  QSettings settings_;
  QString workdir_, last_message_;
  std::shared_ptr<LoadedSet> dst_, src_;
  std::shared_ptr<veneer::pipeline::TransferResult> result_;
  std::shared_ptr<veneer::repaint::Relighter> relighter_;
  // The live repaint: each frame registered to the source's stills, carried
  // through the map, with the outline, a quality figure and a lost state.
  std::shared_ptr<veneer::repaint::LiveSession> live_session_;
  QString live_refusal_;  // the live view's framing could not be related to the stills
  // Made by the transfer's worker, so that showing a result costs the GUI
  // thread almost nothing: the result's picture, the live repainter, the
  // relit pictures for the light direction the run started with.
  cv::Mat result_picture_, pending_result_picture_;
  QImage result_image_, pending_result_image_;  // the same as the result view shows it
  std::shared_ptr<veneer::repaint::LiveSession> pending_session_;
  cv::Mat pending_relit_, pending_relit_source_;
  cv::Vec3d pending_relit_direction_;
  // What a transfer ran with (the options, the hand masks), kept with the
  // result it made so that the library stores the map with them.
  struct RunSettings {
    veneer::pipeline::TransferOptions options;
    cv::Mat dst_hand, src_hand;
    QString reopened;  // the library map it repainted through ("" = matched)
  };
  RunSettings running_, shown_;
  // A library map being reopened: shown once both its sets are loaded.
  struct Reopen {
    LibraryMap entry;
    std::shared_ptr<const veneer::match::Map> map;
    veneer::pipeline::TransferOptions options;
    cv::Mat dst_hand, src_hand;
    bool dst_loaded = false, src_loaded = false;
  };
  std::optional<Reopen> reopen_;
  std::shared_ptr<const veneer::match::Map> given_map_;  // the next transfer repaints through it
  QString reopened_folder_;                              // ... the library map it came from
  std::atomic<bool> cancel_{false};
  bool computing_ = false;
  bool rerun_ = false;  // a matching option changed while computing: run again when done
  int map_only_runs_ = 0;
  int repaint_only_runs_ = 0;  // runs that kept the map shown (only the blend changed)
  int sets_loaded_ = 0;  // counts every set loaded as destination or source
  // The objects prepared for the last transfer and what they were made from
  // (preparationKey); reused while only matching options change.
  std::shared_ptr<const veneer::pipeline::PreparedPair> prepared_, pending_prepared_;
  QString prepared_key_, pending_key_;
  QFutureWatcher<void> transfer_watch_;
  QString transfer_error_, relight_error_;
  std::shared_ptr<veneer::pipeline::TransferResult> pending_result_;
  std::shared_ptr<veneer::repaint::Relighter> pending_relighter_;
  cv::Mat live_frame_, live_repainted_;
  QThreadPool live_pool_;  // the live frames' one worker thread (not the pool computes and exports queue in)
  bool live_busy_ = false;  // a frame is being processed there
  std::optional<veneer::rig::LiveFrame> live_next_;  // the newest frame that came meanwhile
  int live_frames_ = 0;
  double live_fps_ = 0;
  QElapsedTimer live_clock_;
  QRect seg_rect_;
  QString pending_role_;  // "destination"/"source" while a UI capture runs
  std::function<void(veneer::io::Role)> capture_;  // the Capture panel's settings, used by both capture rows
  // live first (live_first.cpp)
  void flowMaybeFullResolution();
  int live_width_ = 1280;
  bool full_running_ = false;
  int full_swaps_ = 0;
  std::shared_ptr<std::atomic<bool>> full_cancel_ = std::make_shared<std::atomic<bool>>(false);
  StepClock full_step_;
  QLabel* full_label_ = nullptr;
  QProgressBar* full_bar_ = nullptr;
  StepClock step_;
  QTimer step_timer_;  // redraws the status line so the time left counts down
  std::map<QString, veneer::io::Role> auto_pulls_;  // rig set id -> role, pulled by the flow
  int loads_running_ = 0;
  std::shared_ptr<std::atomic<bool>> load_cancel_ = std::make_shared<std::atomic<bool>>(false);
  std::atomic<bool> job_cancel_{false};
  bool job_running_ = false;
  QFuture<void> job_future_;
  QPushButton* step_cancel_ = nullptr;

  // widgets
  QTabWidget* tabs_ = nullptr;
  QLineEdit *rig_edit_ = nullptr, *token_edit_ = nullptr, *object_edit_ = nullptr;
  QPushButton *connect_btn_ = nullptr, *compute_btn_ = nullptr, *cancel_btn_ = nullptr;
  QLabel *status_label_ = nullptr, *capture_label_ = nullptr, *transfer_label_ = nullptr,
         *message_label_ = nullptr, *live_label_ = nullptr, *rect_label_ = nullptr, *relight_label_ = nullptr;
  QProgressBar *shot_bar_ = nullptr, *transfer_bar_ = nullptr, *pull_bar_ = nullptr;
  QDoubleSpinBox *shutter_ = nullptr, *aperture_ = nullptr, *threshold_ = nullptr, *coherent_threshold_ = nullptr,
                 *coherent_smooth_ = nullptr, *coherent_guide_ = nullptr, *uniformity_ = nullptr,
                 *blend_guide_ = nullptr,
                 *seg_threshold_ = nullptr, *fps_ = nullptr;
  QSpinBox *iso_ = nullptr, *candidates_ = nullptr, *iterations_ = nullptr, *blend_ = nullptr;
  QComboBox *method_ = nullptr, *feature_ = nullptr, *patch_ = nullptr, *seg_method_ = nullptr, *look_what_ = nullptr,
            *recent_ = nullptr;
  QCheckBox *fast_ = nullptr, *truth_normals_ = nullptr, *live_update_ = nullptr;
  QTreeWidget* sets_tree_ = nullptr;
  QTreeWidgetItem *rig_root_ = nullptr, *local_root_ = nullptr, *trash_root_ = nullptr, *maps_root_ = nullptr;
  QPushButton* undo_btn_ = nullptr;
  QString last_deleted_;  // the rig set the Undo button brings back
  std::unique_ptr<Library> library_;
  ImageView *dst_view_ = nullptr, *src_view_ = nullptr, *result_view_ = nullptr, *origin_view_ = nullptr,
            *live_src_view_ = nullptr, *live_dst_view_ = nullptr, *relight_view_ = nullptr,
            *relight_src_view_ = nullptr;
  SpherePad *relight_pad_ = nullptr, *hand_pad_ = nullptr;
  std::vector<QCheckBox*> lamp_boxes_;
  QHBoxLayout* lamp_row_ = nullptr;
  QPushButton* live_btn_ = nullptr;
  QCheckBox* auto_flow_ = nullptr;
  QComboBox* preset_ = nullptr;
  QLabel *histogram_ = nullptr, *exposure_label_ = nullptr;
  QString exposure_text_;
  bool applying_preset_ = false;
  QLabel* step_label_ = nullptr;
  QDialog* calibration_dialog_ = nullptr;
  QLabel *calibration_label_ = nullptr, *calibration_text_ = nullptr;
  QImage calibration_image_;
  QProgressBar* step_bar_ = nullptr;
};

}  // namespace veneer::app
