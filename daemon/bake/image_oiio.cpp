extern "C" { int lc_image_stub; }
