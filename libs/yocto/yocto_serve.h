//
// # Yocto/Serve: look-dev in a browser
//
// A render session served over HTTP: a render thread accumulates passes and
// publishes each one as a frame; a web page (apps/serve/, compiled in) shows
// the frames and edits the hair materials (the controls come from the hair
// parameter table), the environments' and distant lights' strengths and the
// camera. An edit cancels the pass in flight, restarts the accumulation
// without loading or building again, and first publishes coarse previews
// (fewer pixels, one sample; the first sized to a time budget, each next
// one finer), published at their own size for the page to scale up. Saves write the image
// and the edited scene into the output folder given at start, on the render
// thread between passes, so that a save never sees a torn frame.
//
// Safety: every request, the page included, carries the token (query
// `token=` or header X-Token; 403 otherwise); no CORS header is ever sent;
// bodies are at most serve_body_limit bytes; every edit is validated before
// it changes anything (400 with {"error", "field"} otherwise); static files
// come from the binary, so no request names a path on disk.
//
// Updates: GET /api/state?after=N answers when frame N+1 is published (a
// long poll, at most serve_poll_milliseconds), so a page needs no timer.
//

#ifndef YOCTO_SERVE_H_
#define YOCTO_SERVE_H_

#include <memory>
#include <string>

#include "yocto_render.h"

// -----------------------------------------------------------------------------
// SCENE SERVER
// -----------------------------------------------------------------------------
namespace yocto {

// Largest request body, in bytes.
inline const int serve_body_limit = 4096;
// Longest wait of a long poll of the state (GET /api/state?after=FRAME).
inline const int serve_poll_milliseconds = 250;

struct serve_params {
  std::string host       = "127.0.0.1";  // where it listens
  int         port       = 8000;         // 0: any free port
  std::string output_dir = ".";          // where saves go
  std::string token      = "";           // "" for a random one
  // The first frame after an edit: a preview of one sample at fewer pixels
  // taking about this long; then previews of four times the pixels while
  // they take under a quarter of a full pass.
  double preview_seconds = 0.04;
};

struct serve_state;  // the server's threads and shared state (yocto_serve.cpp)

struct scene_server {
  std::string                  url   = "";  // http://HOST:PORT/?token=TOKEN
  std::string                  token = "";
  int                          port  = 0;
  std::shared_ptr<serve_state> state = nullptr;
};

// Starts serving a built session (build_render_session) on its own threads;
// false with a message if the port cannot be bound or the folder is not
// writable.
bool start_scene_server(scene_server& server, std::unique_ptr<render_session> session,
    const serve_params& params, std::string& error);

// Stops rendering and serving, and joins the threads (safe to call twice).
void stop_scene_server(scene_server& server);

}  // namespace yocto

#endif
