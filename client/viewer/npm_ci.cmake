# cmake -DCLIENT_DIR=... -DNPM=... -DSTAMP=... -P npm_ci.cmake
# Runs `npm ci` in client/ when client/node_modules is missing or older than package-lock.json
# (npm writes node_modules/.package-lock.json on every install), then touches STAMP so the
# viewer bundle is rebuilt; otherwise leaves everything as it is (a cheap check every build).
set(lock ${CLIENT_DIR}/package-lock.json)
set(installed ${CLIENT_DIR}/node_modules/.package-lock.json)
if(NOT EXISTS ${installed} OR ${lock} IS_NEWER_THAN ${installed})
  message(STATUS "viewer: npm ci in ${CLIENT_DIR} (node_modules missing or older than package-lock.json)")
  execute_process(COMMAND ${NPM} ci --no-audit --no-fund WORKING_DIRECTORY ${CLIENT_DIR} RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "viewer: npm ci in ${CLIENT_DIR} failed (${rc})")
  endif()
  file(TOUCH ${STAMP})
elseif(NOT EXISTS ${STAMP})
  file(TOUCH ${STAMP})
endif()
