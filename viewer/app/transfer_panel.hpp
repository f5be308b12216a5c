#pragma once
// The Transfer panel: the presets and the compute settings (the expert ones
// folded under Advanced), Compute and Cancel; the transfer itself runs off the
// GUI thread, reusing the prepared objects (normals, masks) while only a
// matching option changes.
#include <atomic>
#include <memory>

#include <QFutureWatcher>
#include <QGroupBox>

#include "session.hpp"

class QCheckBox;
class QComboBox;
class QDoubleSpinBox;
class QLabel;
class QProgressBar;
class QPushButton;
class QSpinBox;

namespace veneer::app {

class TransferPanel : public QGroupBox {
  Q_OBJECT
 public:
  explicit TransferPanel(Session& session, QWidget* parent = nullptr);
  ~TransferPanel() override;

  void startTransfer();
  void cancelTransfer();
  bool computing() const { return computing_; }
  // Runs the transfer now, or once more after the one running.
  void runOrRerun();
  // Transfers that reused the prepared objects (normals, masks) and
  // recomputed only the map: what a change of a matching option triggers.
  int mapOnlyRuns() const { return map_only_runs_; }
  int repaintOnlyRuns() const { return repaint_only_runs_; }  // runs that kept the map shown (only the blend changed)

  // A library map reopened: its options shown ("as reopened"), and the next
  // transfer repaints through `map` instead of matching.
  void showOptions(const veneer::pipeline::TransferOptions& options);
  void repaintThrough(std::shared_ptr<const veneer::match::Map> map, const QString& library_folder);
  // The full-resolution pair made in the background is now the one prepared.
  void adoptPrepared(std::shared_ptr<const veneer::pipeline::PreparedPair> pair);
  // An option changed (or a hand mask, `hand` then says which sets have one):
  // recomputed once a transfer has been shown.
  void matchOptionChanged();
  void handMaskChanged(const QString& hand);
  // How the stills are painted (the Look tab's selector): shaded or the
  // pixel copy, as `veneer transfer --look`. The default preset follows the
  // look's matching (pipeline::default_transfer_options), a custom one is
  // kept; a result shown is painted again (the map kept when it still fits).
  void setLook(veneer::repaint::Look look);
  veneer::repaint::Look look() const { return look_; }
  // The pair the result shown was made from (as pipeline::prepare_pair or
  // prepare_live_pair made it from the sets' folders; null before a transfer).
  std::shared_ptr<const veneer::pipeline::PreparedPair> prepared() const { return prepared_; }

 signals:
  // A transfer ended, shown, failed or cancelled (before resultShown when shown).
  void transferEnded();
  // A transfer's result is shown now; `relit` and `relit_source` are the
  // relight pictures its worker made for `light` (null when none).
  void resultShown(QImage relit, QImage relit_source, cv::Vec3d light);
  // The look changed here (a library map reopened with its options): the selectors follow.
  void lookShown(veneer::repaint::Look look);

 private:
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
  static std::vector<Preset> presets(veneer::repaint::Look look);
  void applyPreset(const Preset& preset);
  QString preparationKey() const;
  void onTransferDone();

  Session& session_;
  std::atomic<bool> cancel_{false};
  bool computing_ = false;
  bool rerun_ = false;  // a matching option changed while computing: run again when done
  int map_only_runs_ = 0, repaint_only_runs_ = 0;
  bool applying_preset_ = false;
  veneer::repaint::Look look_ = veneer::pipeline::TransferOptions{}.look;
  std::shared_ptr<const veneer::match::Map> given_map_;  // the next transfer repaints through it
  QString reopened_folder_;                              // ... the library map it came from
  RunSettings running_;
  // The objects prepared for the last transfer and what they were made from
  // (preparationKey); reused while only matching options change.
  std::shared_ptr<const veneer::pipeline::PreparedPair> prepared_, pending_prepared_;
  QString prepared_key_, pending_key_;
  // Made by the transfer's worker, so that showing a result costs the GUI
  // thread almost nothing: the result's picture, the live repainter, the
  // relit pictures for the light direction the run started with.
  QFutureWatcher<void> transfer_watch_;
  QString transfer_error_, pending_relight_error_;
  std::shared_ptr<veneer::pipeline::TransferResult> pending_result_;
  std::shared_ptr<veneer::repaint::Relighter> pending_relighter_;
  cv::Mat pending_result_picture_;
  QImage pending_result_image_;
  std::shared_ptr<veneer::repaint::LiveSession> pending_session_;
  QString pending_live_note_;  // why the live session paints the copy only ("" = it paints the look)
  cv::Mat pending_relit_, pending_relit_source_;
  cv::Vec3d pending_relit_direction_;
  QRect seg_rect_;

  QComboBox *preset_ = nullptr, *method_ = nullptr, *feature_ = nullptr, *patch_ = nullptr, *seg_method_ = nullptr;
  QSpinBox *candidates_ = nullptr, *iterations_ = nullptr, *blend_ = nullptr;
  QDoubleSpinBox *threshold_ = nullptr, *coherent_threshold_ = nullptr, *coherent_smooth_ = nullptr,
                 *coherent_guide_ = nullptr, *uniformity_ = nullptr, *blend_guide_ = nullptr, *seg_threshold_ = nullptr;
  QCheckBox *fast_ = nullptr, *truth_normals_ = nullptr, *live_update_ = nullptr;
  QPushButton *compute_btn_ = nullptr, *cancel_btn_ = nullptr;
  QProgressBar* transfer_bar_ = nullptr;
  QLabel *transfer_label_ = nullptr, *rect_label_ = nullptr;
};

}  // namespace veneer::app
