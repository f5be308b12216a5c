// asio's compiled part (sockets, the reactor, the TLS engine), built once here
// for every program: veneer_proto sets ASIO_SEPARATE_COMPILATION for all that
// link it, so the files that use asio (the rig client, the daemon's server)
// include only its templates and not its implementation (issue 49: the rig
// client was the slowest unit of the build).
#include <asio/impl/src.hpp>
#include <asio/ssl/impl/src.hpp>
