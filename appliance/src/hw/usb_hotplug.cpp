// USB arrival/removal through libusb's hotplug callbacks and an event thread.
#include <libusb.h>

#include <atomic>
#include <thread>

#include "veneer/util/log.hpp"
#include "veneerd/hw/gphoto2.hpp"

namespace veneerd::hw {

namespace {

class LibusbHotplug final : public UsbHotplug {
 public:
  ~LibusbHotplug() override { stop(); }

  veneer::Status start(std::function<void(bool, const UsbDeviceId&)> changed) override {
    if (ctx_) return {};
    if (libusb_init(&ctx_) != 0) {
      ctx_ = nullptr;
      return veneer::make_error("libusb could not be initialised");
    }
    if (!libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)) {
      libusb_exit(ctx_);
      ctx_ = nullptr;
      return veneer::make_error("libusb has no hotplug support on this system");
    }
    changed_ = std::move(changed);
    int r = libusb_hotplug_register_callback(
        ctx_, static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
        LIBUSB_HOTPLUG_NO_FLAGS, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
        &LibusbHotplug::callback, this, &handle_);
    if (r != LIBUSB_SUCCESS) {
      libusb_exit(ctx_);
      ctx_ = nullptr;
      return veneer::make_error(std::string("libusb hotplug registration failed: ") + libusb_error_name(r));
    }
    running_ = true;
    thread_ = std::thread([this] {
      while (running_) {
        timeval tv{0, 200000};
        libusb_handle_events_timeout_completed(ctx_, &tv, nullptr);
      }
    });
    return {};
  }

  void stop() override {
    if (!ctx_) return;
    // Deregistering wakes the event thread (libusb_interrupt_event_handler).
    running_ = false;
    libusb_hotplug_deregister_callback(ctx_, handle_);
    if (thread_.joinable()) thread_.join();
    libusb_exit(ctx_);
    ctx_ = nullptr;
  }

 private:
  static int LIBUSB_CALL callback(libusb_context*, libusb_device* dev, libusb_hotplug_event event, void* user) {
    auto* self = static_cast<LibusbHotplug*>(user);
    UsbDeviceId id;
    id.bus = libusb_get_bus_number(dev);
    id.address = libusb_get_device_address(dev);
    libusb_device_descriptor d{};
    if (libusb_get_device_descriptor(dev, &d) == 0) {
      id.vendor = d.idVendor;
      id.product = d.idProduct;
    }
    bool arrived = event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED;
    VLOG_DEBUG("Camera", "USB {:04x}:{:04x} at {:03d},{:03d} {}", id.vendor, id.product, id.bus, id.address,
               arrived ? "arrived" : "left");
    if (self->changed_) self->changed_(arrived, id);
    return 0;  // stay registered
  }

  libusb_context* ctx_ = nullptr;
  libusb_hotplug_callback_handle handle_{};
  std::atomic<bool> running_{false};
  std::thread thread_;
  std::function<void(bool, const UsbDeviceId&)> changed_;
};

}  // namespace

std::unique_ptr<UsbHotplug> make_libusb_hotplug() { return std::make_unique<LibusbHotplug>(); }

}  // namespace veneerd::hw
