// What the PTP/IP twin does as a camera: its device info, the card (objects,
// listing, download, delete), capture through the shot source, and the
// exposure properties.
#include "ptpip_twin_impl.hpp"

#include <cmath>
#include <cstring>

#include "veneer/util/log.hpp"

namespace veneerd {

using namespace ptpip;

std::vector<uint8_t> PtpipTwin::Impl::device_info() const {
  std::vector<uint16_t> ops{op::get_device_info,    op::open_session,          op::close_session,
                            op::get_storage_ids,    op::get_storage_info,      op::get_num_objects,
                            op::get_object_handles, op::get_object_info,       op::get_object,
                            op::delete_object,      op::initiate_capture,      op::get_device_prop_desc,
                            op::get_device_prop_value, op::set_device_prop_value};
  std::vector<uint16_t> props{prop::f_number, prop::focus_mode, prop::exposure_time, prop::program,
                              prop::exposure_index};
  if (opt.preview) {
    ops.push_back(op::get_stream_info);
    ops.push_back(op::get_stream);
    props.push_back(prop::supported_streams);
    props.push_back(prop::enabled_streams);
  }
  Out o;
  o.u16(100).u32(0).u16(0).str("").u16(0);  // PTP 1.00, no vendor extension
  o.array16(ops);
  o.array16(std::vector<uint16_t>{ev::object_added, ev::device_prop_changed, ev::capture_complete});
  o.array16(props);
  o.array16(std::vector<uint16_t>{kFormatJpeg});
  o.array16(std::vector<uint16_t>{kFormatJpeg, kFormatAssociation});
  o.str(opt.manufacturer).str(opt.model).str("1.0").str(opt.serial);
  return std::move(o.bytes());
}

uint16_t PtpipTwin::Impl::list_objects(uint32_t storage, uint32_t format, uint32_t parent, std::vector<uint32_t>& out) {
  if (storage != kAll && storage != kStorage) return rc::invalid_storage_id;
  std::lock_guard lock(mu);
  if (parent != 0 && parent != kAll) {
    auto it = card.find(parent);
    if (it == card.end() || it->second.format != kFormatAssociation) return rc::invalid_parent;
  }
  for (const auto& [h, o] : card) {
    if (format != 0 && o.format != format) continue;
    if (parent == kAll && o.parent != 0) continue;
    if (parent != 0 && parent != kAll && o.parent != parent) continue;
    out.push_back(h);
  }
  return rc::ok;
}

uint16_t PtpipTwin::Impl::object_info(uint32_t handle, std::vector<uint8_t>& data) {
  std::lock_guard lock(mu);
  auto it = card.find(handle);
  if (it == card.end()) return rc::invalid_object_handle;
  const Object& ob = it->second;
  bool folder = ob.format == kFormatAssociation;
  Out o;
  o.u32(kStorage).u16(ob.format).u16(0).u32(ob.bytes ? uint32_t(ob.bytes->size()) : 0);
  o.u16(0).u32(0).u32(0).u32(0);  // no thumbnail
  o.u32(uint32_t(ob.width)).u32(uint32_t(ob.height)).u32(folder ? 0 : 24);
  o.u32(ob.parent).u16(folder ? 1 : 0).u32(0).u32(0);  // generic folder
  o.str(ob.name).str(ob.date).str(ob.date).str("");
  data = std::move(o.bytes());
  return rc::ok;
}

bool PtpipTwin::Impl::get_object(Connection& c, uint32_t tid, uint32_t handle) {
  std::shared_ptr<const std::vector<unsigned char>> bytes;
  size_t file = SIZE_MAX;
  bool drop = false, off = false;
  {
    std::lock_guard lock(mu);
    auto it = card.find(handle);
    if (it != card.end() && it->second.bytes) {
      bytes = it->second.bytes;
      file = it->second.file;
      if (drop_download_in > 0 && --drop_download_in == 0) {
        drop = true;
        off = drop_download_off;
      }
    }
  }
  if (!bytes) return send_response(c.cmd_fd, rc::invalid_object_handle, tid, {});
  if (drop) {
    send_data(c.cmd_fd, tid, bytes->data(), bytes->size(), bytes->size() / 2);
    std::lock_guard lock(mu);
    drop_locked(&c, off, "unplugged halfway through a download");
    return false;
  }
  if (!send_data(c.cmd_fd, tid, bytes->data(), bytes->size())) return false;
  {
    std::lock_guard lock(mu);
    ++stats.downloads;
    if (file < files.size()) ++files[file].downloads;
  }
  return send_response(c.cmd_fd, rc::ok, tid, {});
}

uint16_t PtpipTwin::Impl::delete_object(uint32_t handle) {
  std::lock_guard lock(mu);
  std::vector<uint32_t> gone;
  if (handle == kAll) {
    for (const auto& [h, o] : card)
      if (o.format != kFormatAssociation) gone.push_back(h);
  } else {
    auto it = card.find(handle);
    if (it == card.end()) return rc::invalid_object_handle;
    if (it->second.format == kFormatAssociation) return rc::object_write_protected;
    gone.push_back(handle);
  }
  for (uint32_t h : gone) {
    auto it = card.find(h);
    if (it->second.file < files.size()) files[it->second.file].deleted = true;
    card.erase(it);
    ++stats.deletes;
  }
  return rc::ok;
}

bool PtpipTwin::Impl::capture(Connection& c, uint32_t tid, uint32_t storage, uint32_t format) {
  if (storage != 0 && storage != kStorage) return send_response(c.cmd_fd, rc::invalid_storage_id, tid, {});
  if (format != 0 && format != kFormatJpeg) return send_response(c.cmd_fd, rc::invalid_object_format, tid, {});
  uint64_t shot = 0;
  PtpipExposure e;
  bool drop = false, off = false;
  {
    std::lock_guard lock(mu);
    shot = ++stats.captures;
    e = exposure;
    if (drop_capture_in > 0 && --drop_capture_in == 0) {
      drop = true;
      off = drop_capture_off;
    }
  }
  // The response comes at once; the shot is announced by events when it is
  // on the card (the initiator waits for those without a deadline).
  if (!send_response(c.cmd_fd, rc::ok, tid, {})) return false;
  if (drop) {
    std::lock_guard lock(mu);
    drop_locked(&c, off, "unplugged while exposing");
    return false;
  }
  auto jpeg = opt.shot(e, shot);
  if (!jpeg || jpeg->empty()) {
    // A camera that cannot deliver would leave the initiator waiting for
    // ObjectAdded forever; dropping the connection ends that wait.
    VLOG_ERROR(kLog, "shot {} could not be produced ({}); dropping the connection",
               shot, jpeg ? std::string("empty image") : jpeg.message());
    std::lock_guard lock(mu);
    drop_locked(&c, false, "the shot source failed");
    return false;
  }
  uint32_t handle = 0;
  {
    std::lock_guard lock(mu);
    Object ob;
    ob.handle = handle = next_handle++;
    ob.parent = 2;  // DCIM/100VENER
    ob.format = kFormatJpeg;
    char name[32];
    std::snprintf(name, sizeof name, "IMG_%04u.JPG", unsigned(files.size() % 9999 + 1));
    ob.name = name;
    ob.date = ptp_date_now();
    auto size = jpeg_size(*jpeg);
    ob.width = size.first;
    ob.height = size.second;
    ob.bytes = std::make_shared<const std::vector<unsigned char>>(std::move(*jpeg));
    ob.file = files.size();
    PtpipFile f;
    f.handle = handle;
    f.name = ob.name;
    f.bytes = *ob.bytes;
    f.exposure = e;
    files.push_back(std::move(f));
    card.emplace(handle, std::move(ob));
  }
  VLOG_DEBUG(kLog, "shot {} on the card as handle {}", shot, handle);
  send_event(c, ev::object_added, tid, {handle});
  send_event(c, ev::capture_complete, tid, {});
  return true;
}

// GetDevicePropDesc (desc = true) or GetDevicePropValue.
uint16_t PtpipTwin::Impl::property(uint32_t code, bool desc, std::vector<uint8_t>& data) const {
  Out o;
  auto enum16 = [&](uint16_t c, uint16_t value, uint16_t dflt, const std::vector<uint16_t>& offered) {
    if (!desc) return void(o.u16(value));
    o.u16(c).u16(dtc::uint16).u8(1).u16(dflt).u16(value).u8(2).u16(uint16_t(offered.size()));  // enumeration
    for (auto v : offered) o.u16(v);
  };
  auto enum32 = [&](uint16_t c, uint32_t value, uint32_t dflt, const std::vector<uint32_t>& offered) {
    if (!desc) return void(o.u32(value));
    o.u16(c).u16(dtc::uint32).u8(1).u32(dflt).u32(value).u8(2).u16(uint16_t(offered.size()));
    for (auto v : offered) o.u32(v);
  };
  switch (code) {
    case prop::exposure_time:
      enum32(prop::exposure_time, exposure.exposure_time, opt.initial.exposure_time, opt.exposure_times);
      break;
    case prop::f_number:
      enum16(prop::f_number, exposure.f_number, opt.initial.f_number, opt.f_numbers);
      break;
    case prop::exposure_index:
      enum16(prop::exposure_index, exposure.iso, opt.initial.iso, opt.isos);
      break;
    case prop::program:
      enum16(prop::program, exposure.program, opt.initial.program, {1, 2, 3, 4});
      break;
    case prop::focus_mode:
      enum16(prop::focus_mode, exposure.focus, opt.initial.focus, {1, 2});
      break;
    case prop::supported_streams:
    case prop::enabled_streams: {
      if (!opt.preview) return rc::device_prop_not_supported;
      bool supported = code == prop::supported_streams;
      uint32_t value = supported ? 1u : enabled_streams;  // bit 0: video
      if (!desc) {
        o.u32(value);
        break;
      }
      o.u16(uint16_t(code)).u16(dtc::uint32).u8(supported ? 0 : 1).u32(supported ? 1u : 0u).u32(value).u8(0);
      break;
    }
    default:
      return rc::device_prop_not_supported;
  }
  data = std::move(o.bytes());
  return rc::ok;
}

uint16_t PtpipTwin::Impl::set_property(uint16_t code, const std::vector<uint8_t>& in) {
  auto u16ok = [&] { return in.size() == 2; };
  auto u32ok = [&] { return in.size() == 4; };
  auto in_set = [](const auto& v, auto x) { return std::find(v.begin(), v.end(), x) != v.end(); };
  std::lock_guard lock(mu);
  uint32_t value = 0;
  switch (code) {
    case prop::exposure_time:
      if (!u32ok()) return rc::invalid_prop_format;
      value = get32(in.data());
      if (!in_set(opt.exposure_times, value)) return rc::invalid_prop_value;
      exposure.exposure_time = value;
      break;
    case prop::f_number:
    case prop::exposure_index:
    case prop::program:
    case prop::focus_mode: {
      if (!u16ok()) return rc::invalid_prop_format;
      uint16_t v = get16(in.data());
      value = v;
      if (code == prop::f_number) {
        if (!in_set(opt.f_numbers, v)) return rc::invalid_prop_value;
        exposure.f_number = v;
      } else if (code == prop::exposure_index) {
        if (!in_set(opt.isos, v)) return rc::invalid_prop_value;
        exposure.iso = v;
      } else if (code == prop::program) {
        if (v < 1 || v > 4) return rc::invalid_prop_value;
        exposure.program = v;
      } else {
        if (v < 1 || v > 2) return rc::invalid_prop_value;
        exposure.focus = v;
      }
      break;
    }
    case prop::enabled_streams:
      if (!opt.preview) return rc::device_prop_not_supported;
      if (!u32ok()) return rc::invalid_prop_format;
      value = get32(in.data());
      if (value > 1) return rc::invalid_prop_value;
      enabled_streams = value;
      break;
    case prop::supported_streams:
      return opt.preview ? rc::access_denied : rc::device_prop_not_supported;
    default:
      return rc::device_prop_not_supported;
  }
  writes.emplace_back(code, value);
  ++stats.property_sets;
  VLOG_DEBUG(kLog, "property 0x{:04x} = {}", code, value);
  return rc::ok;
}

}  // namespace veneerd
